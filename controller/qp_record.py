"""Replay the allocation QPs a FullPoseController instance actually solved.

The controller keeps its last guidance and inner-allocation problems in its
state; this reads them from the serialized FMU state (fmi2SerializeFMUstate)
through the controller's host library (``libfp_controller``), so tests and benchmarks
hand the very same problems to other solvers (piqp) without a second copy of the
control law.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from controller.native import solver

GUIDANCE = 0
ALLOCATION = 1
TWIN = 2
_CAP = 96 * 32  # larger than any packed array of the solver caps


@dataclass(frozen=True)
class RecordedQP:
    """min ||A x - b||^2 s.t. lb <= x <= ub, C x <= d; x is the controller's solution."""

    A: np.ndarray
    b: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    C: np.ndarray
    d: np.ndarray
    x: np.ndarray


def qp_from_state(state: bytes, which: int) -> RecordedQP:
    """Extract the last QP (GUIDANCE, ALLOCATION or TWIN) from a serialized controller state."""
    dims = np.zeros(3, dtype=np.int32)
    bufs = [np.zeros(_CAP) for _ in range(7)]
    dp = ctypes.POINTER(ctypes.c_double)
    rc = solver().fp_controller_state_qp(
        state, len(state), which, dims.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)),
        *(b.ctypes.data_as(dp) for b in bufs))
    if rc != 0:
        raise ValueError("not a FullPoseController state")
    nv, nr, nc = (int(v) for v in dims)
    A, b, lb, ub, C, d, x = bufs
    return RecordedQP(A=A[: nr * nv].reshape(nr, nv).copy(), b=b[:nr].copy(),
                      lb=lb[:nv].copy(), ub=ub[:nv].copy(),
                      C=C[: nc * nv].reshape(nc, nv).copy(), d=d[:nc].copy(), x=x[:nv].copy())


DENSE_INF = 1e30
"""The "no bound" of dense QP solvers such as DAQP."""


def dense_form(qp: RecordedQP) -> tuple[np.ndarray, ...]:
    """The QP as min 1/2 x'Hx + f'x s.t. bl <= [x; C x] <= bu, the form of dense solvers such
    as DAQP (``daqp.solve(H, f, C, bu, bl, sense)``): bounds first, fixed variables marked
    as equalities in ``sense`` (DAQP's ACTIVE | IMMUTABLE = 5), then the rows of C."""
    nv = qp.A.shape[1]
    H = np.ascontiguousarray(2.0 * qp.A.T @ qp.A)
    f = -2.0 * qp.A.T @ qp.b
    C = np.ascontiguousarray(qp.C if qp.C.size else np.zeros((0, nv)))
    bu = np.concatenate([np.minimum(qp.ub, DENSE_INF), qp.d])
    bl = np.concatenate([np.maximum(qp.lb, -DENSE_INF), np.full(qp.d.size, -DENSE_INF)])
    sense = np.zeros(bu.size, dtype=np.int32)
    sense[:nv][qp.lb == qp.ub] = 5
    return H, f, C, bu, bl, sense
