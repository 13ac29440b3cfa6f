"""One progress callback: stage, fraction, message; sub-ranges through rescaled."""

from hairport.solver.model.progress import no_progress, rescaled


def test_rescaled_maps_fractions_and_stages():
    seen = []
    solve = rescaled(lambda *call: seen.append(call), 0.1, 0.95, "solve")
    solve("guides", 0.0, "start")
    solve("strands", 1.0, "end")
    inner = rescaled(solve, 0.5, 1.0)
    inner("x", 0.5, "half of the second half")
    assert seen == [("solve", 0.1, "start"), ("solve", 0.95, "end"), ("solve", 0.1 + 0.85 * 0.75,
                                                                         "half of the second half")]
    assert no_progress("a", 0.5, "b") is None
    rescaled(None, 0.0, 1.0)("a", 0.5, "nothing to report to")
