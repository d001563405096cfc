"""Small non-linear least-squares helper shared by the SG fits."""

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
