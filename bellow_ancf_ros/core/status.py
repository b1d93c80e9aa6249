"""Status codes of the forward and inverse problems, their messages, and what "usable" means.

Both vocabularies are :class:`enum.IntEnum`: ``int(status)`` and the JSON of
``to_dict()`` (the CLI's contract) carry the plain number, as in scipy's
``OptimizeResult.status``.  Codes 6 to 8 mean the same in both problems
(an unstable equilibrium, a wall-clock budget, an iteration budget), so a
node can compare a result's status with either enum's member.

The messages live in one table, :data:`MESSAGES`; a solver that knows more
(the load fraction reached, the best error so far) appends it to the
message, never replaces the table's text.
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["DynamicsStatus", "ForwardStatus", "InverseStatus", "MESSAGES", "usable"]


class ForwardStatus(IntEnum):
    """Why a forward solve (the equilibrium of eq. 25) stopped."""

    CONVERGED = 0
    MAX_ITER = 1
    LINE_SEARCH = 2
    SINGULAR = 3
    NONFINITE = 4
    STEP_TOO_SMALL = 5
    UNSTABLE = 6
    TIME_BUDGET = 7
    ITERATION_BUDGET = 8

    @property
    def message(self) -> str:
        """The one-line text of the code (:data:`MESSAGES`)."""
        return MESSAGES[ForwardStatus][self]


class InverseStatus(IntEnum):
    """Why an inverse solve (target pose -> pressures) stopped."""

    REACHED = 0
    UNREACHABLE = 1
    FAILED = 2
    UNSTABLE = 6
    TIME_BUDGET = 7
    ITERATION_BUDGET = 8

    @property
    def message(self) -> str:
        """The one-line text of the code (:data:`MESSAGES`)."""
        return MESSAGES[InverseStatus][self]


class DynamicsStatus(IntEnum):
    """Why a time integration (the dynamic model, docs/dynamics.md) stopped."""

    COMPLETED = 0
    MAX_ITER = 1
    SINGULAR = 3
    NONFINITE = 4
    STEP_TOO_SMALL = 5
    TIME_BUDGET = 7

    @property
    def message(self) -> str:
        """The one-line text of the code (:data:`MESSAGES`)."""
        return MESSAGES[DynamicsStatus][self]


#: The one message table: ``MESSAGES[ForwardStatus][code]``, ``MESSAGES[InverseStatus][code]``
#: (two vocabularies: an ``IntEnum`` member hashes as its number, and 0 means "converged" in one
#: and "target reached" in the other).  Codes 6 to 8 share their text.
_SHARED = {
    6: "converged to an unstable equilibrium (the robot would buckle)",
    7: "wall-clock budget exhausted",
    8: "iteration budget exhausted",
}
MESSAGES = {
    ForwardStatus: {
        ForwardStatus.CONVERGED: "converged",
        ForwardStatus.MAX_ITER: "maximum number of Newton iterations reached",
        ForwardStatus.LINE_SEARCH: "line search failed to reduce the residual",
        ForwardStatus.SINGULAR: "singular Jacobian",
        ForwardStatus.NONFINITE: "non-finite residual",
        ForwardStatus.STEP_TOO_SMALL: "continuation step became too small",
    },
    InverseStatus: {
        InverseStatus.REACHED: "target reached",
        InverseStatus.UNREACHABLE: "target unreachable within the pressure limits",
        InverseStatus.FAILED: "no solution",
    },
    DynamicsStatus: {
        DynamicsStatus.COMPLETED: "integrated to the end time",
        DynamicsStatus.MAX_ITER: "a step's Newton iterations did not converge",
        DynamicsStatus.SINGULAR: "singular iteration matrix",
        DynamicsStatus.NONFINITE: "non-finite state or residual",
        DynamicsStatus.STEP_TOO_SMALL: "step halved to its limit without converging",
        DynamicsStatus.TIME_BUDGET: "wall-clock budget exhausted",
    },
}
for _enum, _table in MESSAGES.items():
    if _enum is DynamicsStatus:
        continue
    _table.update({_enum(code): text for code, text in _SHARED.items()})


def usable(converged: bool, stable: bool | None) -> bool:
    """Whether an equilibrium may be used as the robot's configuration.

    Converged, and not found unstable: ``stable`` is None when the caller
    skipped the stability check (``check_stability=False``), and such a
    result counts as usable, since nothing says otherwise.
    """
    return bool(converged and stable is not False)
