"""Least-squares helpers shared by the SG fits (non-linear; non-negative linear)."""

from __future__ import annotations

import numpy as np


def levenberg_marquardt(resid, x, iterations: int, fd_step, tries: int = 8,
                        min_gain: float = 1e-6):
    """Minimise ``|resid(x)|^2`` from ``x`` by Levenberg-Marquardt with a forward
    finite-difference Jacobian (``fd_step(value)``: the step for one parameter) and
    Marquardt's diagonal scaling; up to ``tries`` damping increases per iteration, stop
    when no step helps or the relative gain falls below ``min_gain``.  Returns
    ``(x, residual)``."""
    x = np.array(x, dtype=np.float64)
    r = resid(x)
    cost = float(r @ r)
    damp = 1e-2
    for _ in range(iterations):
        J = np.empty((r.size, x.size))
        for j in range(x.size):
            e = fd_step(x[j])
            xp = x.copy()
            xp[j] += e
            J[:, j] = (resid(xp) - r) / e
        JTJ = J.T @ J
        g = J.T @ r
        gain = 0.0
        improved = False
        for _ in range(tries):
            step = np.linalg.solve(JTJ + damp * np.diag(np.diag(JTJ) + 1e-12), -g)
            xn = x + step
            rn = resid(xn)
            cn = float(rn @ rn)
            if cn < cost:
                gain = (cost - cn) / max(cost, 1e-300)
                x, r, cost = xn, rn, cn
                damp = max(damp / 3.0, 1e-9)
                improved = True
                break
            damp *= 4.0
        if not improved or gain < min_gain:
            break
    return x, r


def nonnegative_least_squares(A, b, tol: float | None = None):
    """``argmin_{x >= 0} |A x - b|`` by Lawson & Hanson's active-set method (1974,
    ch. 23): move the variable with the largest gradient component into the passive
    set, solve the unconstrained problem on that set, and step back toward the
    previous point while any passive variable would turn negative.  The sub-problems
    are solved on the Gram matrix ``A^T A`` (Bro & De Jong's "fast NNLS"), so a tall
    ``A`` is read once.  Exact for the small problems of the SG fits (tens of
    columns).  Returns ``x`` (n,)."""
    A = np.asarray(A, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    m, n = A.shape
    x = np.zeros(n)
    if n == 0 or not np.any(b):
        return x
    if tol is None:
        tol = 10.0 * np.finfo(np.float64).eps * max(m, n) * max(np.abs(A).max(initial=0.0), 1e-300)
    AtA = A.T @ A
    Atb = A.T @ b
    scale = tol * max(float(np.abs(b).max()), 1.0)
    passive = np.zeros(n, dtype=bool)
    w = Atb - AtA @ x
    for _ in range(3 * n + 10):
        free = ~passive
        if not np.any(free) or np.max(np.where(free, w, -np.inf)) <= scale:
            break
        passive[int(np.argmax(np.where(free, w, -np.inf)))] = True
        while True:
            z = np.zeros(n)
            idx = np.flatnonzero(passive)
            G = AtA[np.ix_(idx, idx)]
            try:
                z[idx] = np.linalg.solve(G, Atb[idx])
                if not np.all(np.isfinite(z[idx])):
                    raise np.linalg.LinAlgError
            except np.linalg.LinAlgError:          # dependent columns: least norm
                z[idx] = np.linalg.lstsq(G, Atb[idx], rcond=None)[0]
            if np.all(z[passive] > 0.0):
                x = z
                break
            hit = passive & (z <= 0.0)
            alpha = np.min(x[hit] / np.maximum(x[hit] - z[hit], 1e-300))
            x = x + alpha * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
            if not np.any(passive):
                break
        w = Atb - AtA @ x
    return x
