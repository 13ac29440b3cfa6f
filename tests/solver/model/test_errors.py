"""Input errors name their source and carry a stable code."""

from hairport.solver.model.errors import InputError, TopologyMismatch


def test_message_source_and_code():
    error = InputError("the file ends early", "groom.data", "truncated")
    assert str(error) == "groom.data: the file ends early" and error.problem == "the file ends early"
    assert (error.source, error.code) == ("groom.data", "truncated") and isinstance(error, ValueError)
    assert str(InputError("bad")) == "bad" and InputError("bad").code == "invalid_input"
    assert TopologyMismatch("differs", "b.obj").code == "topology_mismatch"
