"""Errors raised on bad input.

Every reader and validator raises :class:`InputError` naming the file (or argument) and
the problem, so that the CLI can print one line and the service can answer 422. Inputs that
pass every check but admit no valid result hairport can find (a target body that traps hair
inside it, :class:`PenetrationRemaining`) raise one too: the job fails with its code.
"""

from __future__ import annotations


class InputError(ValueError):
    """Input that hairport refuses, with the source it came from and the problem.

    Parameters
    ----------
    problem : str
        What is wrong, in words a user can act on.
    source : str, optional
        The file name or argument the input came from.
    code : str
        A stable machine-readable code (``"truncated"``, ``"non_finite"``, ...).
    """

    def __init__(self, problem: str, source: str | None = None, code: str = "invalid_input"):
        self.problem = problem
        self.source = source
        self.code = code
        super().__init__(f"{source}: {problem}" if source else problem)


class TopologyMismatch(InputError):
    """Source and target characters do not share one mesh topology."""

    def __init__(self, problem: str, source: str | None = None):
        super().__init__(problem, source, code="topology_mismatch")


class PenetrationRemaining(InputError):
    """Hair particles stay inside the target body after the solve and a push-out: no result
    that keeps the hair out of this body was found, and none is reported as one (code
    ``penetration_remaining``)."""

    def __init__(self, problem: str, source: str | None = None):
        super().__init__(problem, source, code="penetration_remaining")


#: what a reader's arithmetic on hostile counts can raise beyond its own checks (an index
#: past int64, a nesting past the recursion limit); the readers' entry points turn these into
#: an InputError with code ``bad_file``, so no crafted file reaches a caller as an internal error
PARSER_FAILURES = (OverflowError, RecursionError)


def parser_failure(error: BaseException, source: str | None) -> InputError:
    """The :class:`InputError` (code ``bad_file``) of a :data:`PARSER_FAILURES` exception."""
    return InputError(f"the file cannot be read: {type(error).__name__}", source, "bad_file")
