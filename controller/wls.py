"""Python binding of the C allocation solver (``fmu_src/common/wls.c``).

Solves ``min ||A x - b||^2  s.t.  lb <= x <= ub,  C x <= d`` with the same
active-set code the controller FMU runs (no Python re-implementation).

The working set is an ``int8`` array of length ``n_vars + n_cons``: first one
entry per variable (-1 at its lower bound, +1 at its upper bound, 0 free), then
one per row of ``C`` (1 active, 0 not).  Pass the ``working_set`` of a result
to the next :func:`solve` to warm-start, or keep a :class:`WlsSolver`, which
warm-starts from its previous solve by itself.

Statuses (see ``wls.h`` for what ``x`` is in each case; it is never NaN):
``"optimal"``, ``"max_iter"``, ``"infeasible"``, ``"bad_input"``.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from controller.native import solver

STATUS_NAMES: tuple[str, ...] = ("optimal", "max_iter", "infeasible", "bad_input")

_DP = ctypes.POINTER(ctypes.c_double)
_I8P = ctypes.POINTER(ctypes.c_int8)
_I32P = ctypes.POINTER(ctypes.c_int32)


@dataclass(frozen=True)
class WlsResult:
    """Outcome of one solve."""

    x: NDArray[np.float64]
    status: str
    iterations: int
    phase1_iterations: int
    objective: float
    max_violation: float
    working_set: NDArray[np.int8]
    warm_start: bool


@cache
def caps() -> tuple[int, int, int]:
    """Size caps compiled into the solver: (max variables, max rows of A, max rows of C)."""
    out = np.zeros(3, dtype=np.int32)
    solver().fp_wls_caps(out.ctypes.data_as(_I32P))
    return int(out[0]), int(out[1]), int(out[2])


def _dptr(a: NDArray[np.float64] | None) -> object:
    return None if a is None else a.ctypes.data_as(_DP)


def _vector(v: ArrayLike | None, n: int, fill: float, name: str) -> NDArray[np.float64]:
    if v is None:
        return np.full(n, fill)
    out = np.ascontiguousarray(np.asarray(v, dtype=np.float64).reshape(-1))
    if out.shape != (n,):
        raise ValueError(f"{name} must have {n} entries, got {out.size}")
    return out


class WlsSolver:
    """One solver instance (one C ``FpWls``): keeps x and the working set between solves."""

    def __init__(self, n_vars: int, n_rows: int, n_cons: int = 0) -> None:
        max_vars, max_rows, max_cons = caps()
        if not (1 <= n_vars <= max_vars and 0 <= n_rows <= max_rows and 0 <= n_cons <= max_cons):
            raise ValueError(
                f"sizes (vars={n_vars}, rows={n_rows}, cons={n_cons}) exceed the caps "
                f"({max_vars}, {max_rows}, {max_cons})"
            )
        lib = solver()
        words = (lib.fp_wls_size() + 7) // 8
        self._buf = (ctypes.c_double * words)()
        if lib.fp_wls_setup_api(self._buf, n_vars, n_rows, n_cons) != 0:
            raise RuntimeError("fp_wls_setup failed")
        self.n_vars, self.n_rows, self.n_cons = n_vars, n_rows, n_cons

    @property
    def working_set(self) -> NDArray[np.int8]:
        """The working set of the last solve, one int8 per variable bound and constraint."""
        ws = np.zeros(self.n_vars + self.n_cons, dtype=np.int8)
        solver().fp_wls_get_working_set_api(self._buf, ws.ctypes.data_as(_I8P))
        return ws

    @working_set.setter
    def working_set(self, ws: ArrayLike) -> None:
        """Start the next solve from this working set (a warm start)."""
        arr = np.ascontiguousarray(np.asarray(ws, dtype=np.int8).reshape(-1))
        if arr.shape != (self.n_vars + self.n_cons,):
            raise ValueError(f"working set must have {self.n_vars + self.n_cons} entries")
        solver().fp_wls_set_start_api(self._buf, None, arr.ctypes.data_as(_I8P))

    def set_x(self, x0: ArrayLike) -> None:
        """Start point of the next solve (used for a cold start and for a rank-deficient A)."""
        arr = _vector(x0, self.n_vars, 0.0, "x0")
        solver().fp_wls_set_start_api(self._buf, _dptr(arr), None)

    def keep_rows(self) -> None:
        """Tell the next solve that C is exactly the last solve's, as the controller does while
        its force set is constant: the solve keeps the rows' checks and norms and reads only
        d.  Any :meth:`set_data` with a C cancels it; it holds for one solve."""
        if solver().fp_wls_keep_rows_api(self._buf) != 0:
            raise RuntimeError("fp_wls_keep_rows failed")

    def reset(self) -> None:
        """Forget the working set: the next solve starts cold."""
        self.working_set = np.zeros(self.n_vars + self.n_cons, dtype=np.int8)

    def set_data(
        self,
        A: ArrayLike,
        b: ArrayLike,
        lb: ArrayLike | None = None,
        ub: ArrayLike | None = None,
        C: ArrayLike | None = None,
        d: ArrayLike | None = None,
    ) -> None:
        """Set the problem data: A (rows x vars), b, the bounds lb, ub (default unbounded) and the
        constraints C x <= d (C None keeps the stored rows: a constant set)."""
        n, m, p = self.n_vars, self.n_rows, self.n_cons
        a = np.ascontiguousarray(np.asarray(A, dtype=np.float64))
        if a.shape != (m, n):
            raise ValueError(f"A must be {m}x{n}, got {a.shape}")
        bb = _vector(b, m, 0.0, "b")
        lo = _vector(lb, n, -np.inf, "lb")
        hi = _vector(ub, n, np.inf, "ub")
        cc: NDArray[np.float64] | None
        dd: NDArray[np.float64] | None
        if p > 0:
            if d is None:
                raise ValueError(f"d is needed for {p} constraints")
            cc = None  # C None: the stored rows stay (a constant set, see keep_rows)
            if C is not None:
                cc = np.ascontiguousarray(np.asarray(C, dtype=np.float64))
                if cc.shape != (p, n):
                    raise ValueError(f"C must be {p}x{n}, got {cc.shape}")
            dd = _vector(d, p, 0.0, "d")
        else:
            cc = dd = None  # no equality rows: NULL pointers
        rc = solver().fp_wls_set_data_api(
            self._buf, _dptr(a), _dptr(bb), _dptr(lo), _dptr(hi), _dptr(cc), _dptr(dd)
        )
        if rc != 0:
            raise RuntimeError("fp_wls_set_data failed")

    def _result(self, x: NDArray[np.float64], info: NDArray[np.int32], fout: NDArray) -> WlsResult:
        status = int(info[0])
        return WlsResult(
            x=x,
            status=STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else "unknown",
            iterations=int(info[1]),
            phase1_iterations=int(info[2]),
            objective=float(fout[0]),
            max_violation=float(fout[1]),
            working_set=self.working_set,
            warm_start=bool(info[3]),
        )

    def solve_stored(self, max_iter: int = 100) -> WlsResult:
        """Solve the data already stored (by :meth:`set_data`)."""
        x = np.zeros(self.n_vars)
        info = np.zeros(4, dtype=np.int32)
        fout = np.zeros(2)
        solver().fp_wls_solve_api(
            self._buf, int(max_iter), _dptr(x), info.ctypes.data_as(_I32P), _dptr(fout)
        )
        return self._result(x, info, fout)

    def solve(
        self,
        A: ArrayLike,
        b: ArrayLike,
        lb: ArrayLike | None = None,
        ub: ArrayLike | None = None,
        C: ArrayLike | None = None,
        d: ArrayLike | None = None,
        max_iter: int = 100,
    ) -> WlsResult:
        """Store the data and solve, warm-started from the previous solve."""
        self.set_data(A, b, lb, ub, C, d)
        return self.solve_stored(max_iter)

    def bench(self, max_iter: int, repeats: int) -> tuple[NDArray[np.float64], WlsResult]:
        """Solve the stored data `repeats` times from the same start, timed in C.

        Returns each solve's wall time in ns and the last solve's result (the
        solver is left as after that solve).
        """
        ns = np.zeros(int(repeats))
        x = np.zeros(self.n_vars)
        info = np.zeros(4, dtype=np.int32)
        fout = np.zeros(2)
        solver().fp_wls_bench_api(
            self._buf,
            int(max_iter),
            int(repeats),
            _dptr(ns),
            _dptr(x),
            info.ctypes.data_as(_I32P),
            _dptr(fout),
        )
        return ns, self._result(x, info, fout)


def solve(
    A: ArrayLike,
    b: ArrayLike,
    lb: ArrayLike | None = None,
    ub: ArrayLike | None = None,
    C: ArrayLike | None = None,
    d: ArrayLike | None = None,
    max_iter: int = 100,
    working_set: ArrayLike | None = None,
    x0: ArrayLike | None = None,
) -> WlsResult:
    """Solve one problem; ``None`` bounds are infinite, ``C``/``d`` optional.

    ``working_set`` (from a previous result) warm-starts the solve; ``x0`` is the
    start point of a cold start (default zero).
    """
    a = np.asarray(A, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError("A must be a matrix")
    m, n = a.shape
    p = 0 if C is None else np.asarray(C).reshape(-1, n).shape[0]
    solver = WlsSolver(n, m, p)
    solver.set_data(a, b, lb, ub, None if p == 0 else np.asarray(C).reshape(p, n), d)
    if x0 is not None:
        solver.set_x(x0)
    if working_set is not None:
        solver.working_set = working_set
    return solver.solve_stored(max_iter)
