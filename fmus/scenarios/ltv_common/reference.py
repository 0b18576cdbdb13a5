"""Independent monolithic reference for paper 001: plant + filters (2)-(6) + estimator + (10).

Written from the paper's equations only -- it imports nothing from the project -- and solved
as ONE ODE with scipy's ``solve_ivp``.  The tests compare the observer block and the
co-simulated FMUs against it.

Monolithic state (n = 2 states, p = 4 n = 8 unknowns):

* plant (1): ``x' = A(t) x + k y + b u + m f(y)``, ``y = C^T x`` (the proof's ``A(t) + k C^T``);
* filters (2)-(6) as one n x (1 + 4 n) matrix ``S = [xi, eta, zeta, rho, Phi]``:
  ``xi' = A0 xi + L y``, ``eta' = A0 eta + I y``, ``zeta' = A0 zeta + I u``,
  ``rho' = A0 rho + I f(y)``, ``Phi' = A0 Phi``, ``A0 = A - L C^T``; zero initial values except
  ``Phi(0) = I``;
* regression (7): ``z = y - C^T xi = Psi Theta``, ``Psi = [-C^T Phi, C^T eta, C^T zeta, C^T rho]``,
  ``Theta = [theta; k; b; m]``, ``theta = -x(0)``;
* estimator, either the paper's form (``form="F"``, the default)
  ``Theta_hat' = gamma F Psi^T (z - Psi Theta_hat)``, ``F' = -gamma F Psi^T Psi F + beta F``
  (``F <= M`` holds in every run here, which :func:`simulate` checks), or the equivalent
  information form (``form="information"``) ``P = F^-1``, ``P' = gamma Psi^T Psi - beta P``,
  ``q' = gamma Psi^T z - beta q``, ``Theta_hat = P^-1 q``;
* state estimate (10): ``x_hat = xi - Phi theta_hat + eta k_hat + zeta b_hat + rho m_hat``.

Paper example: ``A(t) = [[2 - sin t, 1], [-8 + cos t, 0]]``, ``C = [1; 0]``,
``L(t) = [2 - sin t; 1 + cos t]`` (so ``A0 = [[0, 1], [-9, 0]]``), ``f = sin``, ``u = sin t``.

How it is solved: the system is not stiff except for the estimator's first ~0.1 s
(``gamma Psi F Psi^T ~ 1e4`` 1/s at t = 0, < 40 after 0.1 s), and the paper case's output
oscillates at up to ~3e3 rad/s late in the run (``m sin(y)``), so an explicit 8th-order method
(DOP853) at rtol = atol = 1e-12 is both fast and accurate.  The estimate is integrated in the
paper's ``F`` form: the information form gives ``Theta_hat = P^-1 q`` with ``P`` ill-conditioned
(eigenvalues from ~1e-3 to ~1e9 in the paper case), which turns the solver's relative error of
``P`` and ``q`` into an error of ~1e-6 in ``Theta_hat`` (measured in ``docs/paper001.md``).

Run as a script to print the convergence numbers quoted in ``docs/paper001.md``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

N = 2
P_DIM = 4 * N
C = np.array([1.0, 0.0])
PAPER = dict(k=[-1.0, 3.0], b=[1.0, 2.0], m=[-4.0, 4.0], x0=[-3.0, -2.0])
BOUNDED = dict(k=[-3.0, 1.0], b=[0.5, -1.0], m=[-2.0, 3.0], x0=[2.0, -1.0])
GAINS = dict(gamma=1000.0, beta=1.0, f0=0.1, M=1e12)
#: solver and tolerances of the stored references (convergence check in ``docs/paper001.md``)
METHOD, RTOL, ATOL = "DOP853", 1e-12, 1e-12

# flat layout: x | S (n x (1 + 4n), row-major) | estimator vector (p) | estimator matrix (p x p)
_X = slice(0, N)
_S = slice(N, N + N * (1 + 4 * N))
_V = slice(_S.stop, _S.stop + P_DIM)
_MAT = slice(_V.stop, _V.stop + P_DIM * P_DIM)
_SIZE = _MAT.stop
# the inputs of the filters (2)-(5): column 0 gets L y, the columns of eta, zeta, rho get I y, I u, I f(y)
_INPUT_Y, _INPUT_U, _INPUT_F = (np.hstack([np.zeros((N, 1 + i * N)), np.eye(N), np.zeros((N, (3 - i) * N))])
                                for i in range(3))


def A_of_t(t):
    return np.array([[2.0 - np.sin(t), 1.0], [-8.0 + np.cos(t), 0.0]])


def L_of_t(t):
    return np.array([2.0 - np.sin(t), 1.0 + np.cos(t)])


def u_of_t(t):
    return np.sin(t)


def true_theta(k, b, m, x0):
    """``Theta = [theta; k; b; m]`` with ``theta = -x(0)``."""
    return np.concatenate([-np.asarray(x0, float), k, b, m])


def _regressor(S):
    """``(C^T xi, Psi)`` from the filter matrix ``S = [xi, eta, zeta, rho, Phi]``."""
    CS = C @ S
    psi = np.concatenate([-CS[1 + 3 * N:], CS[1:1 + 3 * N]])
    return CS[0], psi


def simulate(times, k, b, m, x0, gamma=1000.0, beta=1.0, f0=0.1, M=1e12, form="F",
             rtol=RTOL, atol=ATOL, u=u_of_t, noise=None, method=METHOD):
    """Solve the monolithic ODE on ``[0, times[-1]]``; values at ``times``.

    ``method`` is the ``solve_ivp`` method (``benchmarks/cosimulation_costs.py`` times ``LSODA``).

    ``noise`` (optional, ``t -> v``) is added to the output the observer measures,
    ``y_m = C^T x + v``; the plant itself uses the true ``y``.

    Returns a dict of arrays (one row per time): ``t``, ``x``, ``x_hat``, ``theta_hat``,
    ``F_max`` (largest eigenvalue of ``F``) and the solver's ``nfev``.
    """
    k, b, m = (np.asarray(v, float) for v in (k, b, m))

    def rhs(t, s):
        x = s[_X]
        S = s[_S].reshape(N, 1 + 4 * N)
        y = C @ x
        y_m = y + (noise(t) if noise is not None else 0.0)
        A, L, u_t = A_of_t(t), L_of_t(t), u(t)
        A0 = A - np.outer(L, C)
        f_y = np.sin(y_m)
        dS = A0 @ S + _INPUT_Y * y_m + _INPUT_U * u_t + _INPUT_F * f_y                   # (2)-(6)
        dS[:, 0] += L * y_m
        c_xi, psi = _regressor(S)
        z = y_m - c_xi                                                                  # (7)
        d = np.empty_like(s)
        d[_X] = A @ x + k * y + b * u_t + m * np.sin(y)                                 # (1)
        d[_S] = dS.ravel()
        if form == "F":
            theta, F = s[_V], s[_MAT].reshape(P_DIM, P_DIM)
            Fpsi = F @ psi
            d[_V] = gamma * Fpsi * (z - psi @ theta)
            d[_MAT] = (beta * F - gamma * np.outer(Fpsi, Fpsi)).ravel()
        else:
            d[_V] = gamma * psi * z - beta * s[_V]
            d[_MAT] = gamma * np.outer(psi, psi).ravel() - beta * s[_MAT]
        return d

    s0 = np.zeros(_SIZE)
    s0[_X] = x0
    S0 = np.zeros((N, 1 + 4 * N))
    S0[:, 1 + 3 * N:] = np.eye(N)
    s0[_S] = S0.ravel()
    s0[_MAT] = (np.eye(P_DIM) / f0 if form == "F" else np.eye(P_DIM) * f0).ravel()
    times = np.asarray(times, float)
    sol = solve_ivp(rhs, (0.0, times[-1]), s0, method=method, t_eval=times, rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(sol.message)
    out = {key: [] for key in ("x", "x_hat", "theta_hat", "F_max")}
    for s in sol.y.T:
        matrix = s[_MAT].reshape(P_DIM, P_DIM)
        if form == "F":
            theta_hat, F = s[_V], matrix
        else:
            theta_hat, F = np.linalg.solve(matrix, s[_V]), np.linalg.inv(matrix)
        S = s[_S].reshape(N, 1 + 4 * N)
        xi, Phi = S[:, 0], S[:, 1 + 3 * N:]
        blocks = [S[:, 1 + i * N:1 + (i + 1) * N] for i in range(3)]        # eta, zeta, rho
        th, *kbm = np.split(theta_hat, 4)
        out["x"].append(s[_X])
        out["x_hat"].append(xi - Phi @ th + sum(B @ v for B, v in zip(blocks, kbm)))
        out["theta_hat"].append(theta_hat)
        out["F_max"].append(np.linalg.eigvalsh(0.5 * (F + F.T))[-1])
    out = {key: np.asarray(value) for key, value in out.items()}
    out["t"], out["nfev"] = sol.t, sol.nfev
    if form == "F" and np.any(out["F_max"] > M):
        raise RuntimeError("F exceeded M: this reference does not model the bound")
    return out


def simulate_plant(times, k, b, m, x0, u=u_of_t, rtol=1e-10, atol=1e-10):
    """The plant (1) alone, ``x(t)`` at ``times`` (Radau)."""
    k, b, m = (np.asarray(v, float) for v in (k, b, m))

    def rhs(t, x):
        y = C @ x
        return A_of_t(t) @ x + k * y + b * u(t) + m * np.sin(y)

    times = np.asarray(times, float)
    sol = solve_ivp(rhs, (0.0, times[-1]), np.asarray(x0, float), method="Radau", t_eval=times,
                    rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol.y.T


def convergence_time(t, error, level):
    """First time after which ``max |error|`` (over columns) stays below ``level`` (inf if never)."""
    magnitude = np.abs(error).max(axis=1) if np.ndim(error) > 1 else np.abs(error)
    above = np.nonzero(magnitude >= level)[0]
    if above.size == 0:
        return float(t[0])
    return float("inf") if above[-1] == len(t) - 1 else float(t[above[-1] + 1])


def write_csv(path, case, T, grid=0.05, **options):
    """Solve ``case`` on ``0:grid:T`` and write ``t, Theta(8), Theta_hat(8), x(2), x_hat(2)`` as CSV."""
    times = np.linspace(0.0, T, int(round(T / grid)) + 1)
    out = simulate(times, **case, **options)
    theta = np.tile(true_theta(**case), (times.size, 1))
    header = ",".join(["t"] + [f"theta[{j}]" for j in range(1, 9)] + [f"theta_hat[{j}]" for j in range(1, 9)]
                      + ["x[1]", "x[2]", "x_hat[1]", "x_hat[2]"])
    np.savetxt(path, np.column_stack([out["t"], theta, out["theta_hat"], out["x"], out["x_hat"]]), delimiter=",",
               fmt="%.12g", header=f"paper 001 monolithic reference (fmus/scenarios/ltv_common/reference.py), "
                                  f"{options.get('method', METHOD)}, rtol = {options.get('rtol', RTOL):g}, "
                                  f"atol = {options.get('atol', ATOL):g}\n{header}")


def _main(argv):  # pragma: no cover - prints the numbers quoted in the docs, writes the scenario references
    import argparse
    import time

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="write the scenarios' reference.csv (ltv_ls, ltv_ls_bounded)")
    args = parser.parse_args(argv)
    scenarios = Path(__file__).resolve().parent.parent
    for name, case, T, folder in (("paper", PAPER, 15.0, "ltv_ls"), ("bounded", BOUNDED, 20.0, "ltv_ls_bounded")):
        start = time.process_time()
        out = simulate(np.linspace(0.0, T, int(round(T * 100)) + 1), **case)
        cpu = time.process_time() - start
        error = out["theta_hat"] - true_theta(**case)
        relative = np.abs(out["x_hat"] - out["x"]) / (1.0 + np.abs(out["x"]))
        print(f"{name}: |Theta_hat - Theta| at {T:g} s = {np.abs(error[-1]).max():.2e}, "
              f"< 1e-3 from {convergence_time(out['t'], error, 1e-3):.2f} s; relative state error "
              f"{relative[-1].max():.2e}, < 1e-3 from {convergence_time(out['t'], relative, 1e-3):.2f} s; "
              f"max F {out['F_max'].max():.3g}; max |y| {np.abs(out['x'][:, 0]).max():.3g}; "
              f"{METHOD} {cpu:.1f} s CPU ({out['nfev']} evaluations)")
        if args.write:
            write_csv(scenarios / folder / "reference.csv", case, T)


if __name__ == "__main__":
    import sys

    _main(sys.argv[1:])
