"""Helpers of the command-line tests: arguments, in-process runs, the one-line error contract.

Contract under test (README, "Command line"; docs/cli.md): bad input exits with code 2 and ONE line
``hairport: error: <file>: <problem>`` on stderr (with ``--quiet``; otherwise progress lines
precede it); every output (hair, report, preview) is written to a temporary name and
renamed at the end, so a failed run leaves nothing, not even a temporary ``.part`` file."""

from __future__ import annotations

from pathlib import Path

from hairport import cli

BASELINE = "root-translate+pushout"


N_STRANDS = 60


N_PARTICLES = 12


def retarget_args(world, out: Path, *, source=None, target=None, hair=None, method=BASELINE,
                  extra=(), quiet=True, all_outputs=True) -> list[str]:
    d = world["dir"]
    args = [
        "retarget",
        "--source", str(source or d / "source.obj"),
        "--target", str(target or d / "target.obj"),
        "--hair", str(hair or d / "hair.data"),
        "--out", str(out / "result.data"),
        "--method", method,
    ]
    if all_outputs:
        args += ["--report", str(out / "report.json"), "--preview", str(out / "preview.png")]
    if quiet:
        args.append("--quiet")
    return args + list(extra)


def run(capsys, args: list[str]) -> tuple[int, str, str]:
    capsys.readouterr()  # drop anything printed by fixtures
    code = cli.main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_input_error(code: int, err: str, *keywords: str) -> str:
    """Exit code 2, stderr exactly one 'hairport: error:' line holding every keyword."""
    assert code == cli.EXIT_BAD_INPUT == 2, err
    lines = err.splitlines()
    assert len(lines) == 1, f"expected one stderr line, got {len(lines)}:\n{err}"
    line = lines[0]
    assert line.startswith("hairport: error:"), line
    for word in keywords:
        assert word.lower() in line.lower(), f"{word!r} not in {line!r}"
    return line


def assert_nothing_written(out: Path) -> None:
    left = sorted(p.name for p in out.iterdir())  # hidden temporaries (.result.*.part.data) included
    assert left == [], f"a failed run left files behind: {left}"


def call_log(monkeypatch, module, name: str) -> list:
    """Wrap ``module.name`` so calls are recorded (and still performed)."""
    original = getattr(module, name)
    calls = []

    def wrapper(*args, **kwargs):
        calls.append(args)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapper)
    return calls
