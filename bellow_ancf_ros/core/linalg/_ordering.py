"""Level order of the KKT unknowns: a banded ordering by height along the robot.

Both factorisations of the KKT matrix (eq. 27) use it: the banded LU
(:mod:`core.linalg._kkt`) for its bandwidth, the envelope LDL^T
(:mod:`core.linalg._ldlt`) for its envelope and its pivot-free order.
"""

from __future__ import annotations

import numpy as np

__all__ = ["level_order"]


def level_order(model):
    """Permutation of the KKT unknowns by height along the robot (a banded order).

    Every unknown gets a level ``t``: segment ``j`` spans ``[j (1 + g), j (1 + g) + 1]``
    with ``g = 1/(2n)``, nodes and attachments sit at their material fraction,
    plates at theirs; the gap ``g`` puts the next segment's base (its nodes
    and attachment multipliers) on a level of its own after the connector's
    plate.  Within a level: attachment multipliers, actuator nodes,
    orthonormality multipliers, plate coordinates, each actuator by actuator
    (of the orders tried, the one with the smallest bandwidth for one and two
    segments: 43 for both with six elements).
    """
    n = model.n
    N = model.N
    gap = 1.0 + 0.5 / n
    t = np.empty(N)
    rank = np.empty(N, dtype=np.int64)
    act = np.zeros(N, dtype=np.int64)
    node_t = model.seg_of_act[:, None] * gap + np.arange(model.n_nodes)[None, :] / n  # (A, n+1)
    t[: model.nq_act] = np.repeat(node_t.ravel(), 6)
    rank[: model.nq_act] = 1
    act[: model.nq_act] = np.repeat(np.arange(model.A), model.n_nodes * 6)
    plate_t = np.zeros(model.P)
    for pl in model.plates:
        if pl["unknown"] >= 0 and pl["fraction"] > 0:
            plate_t[pl["unknown"]] = pl["segment"] * gap + pl["fraction"]
    t[model.nq_act:model.nq] = np.repeat(plate_t, 12)
    rank[model.nq_act:model.nq] = 3
    att = slice(model.nq, model.nq + 5 * model.G)
    att_t = model.seg_of_act[model.att_act] * gap + ((model.att_elem % n) + model.att_xi) / n
    t[att] = np.repeat(att_t, 5)
    rank[att] = 0
    act[att] = np.repeat(model.att_act, 5)
    t[model.nq + 5 * model.G:] = np.repeat(plate_t, 6)
    rank[model.nq + 5 * model.G:] = 2
    return np.lexsort((np.arange(N), act, rank, np.round(t, 9)))
