"""Independent monolithic reference for paper 004: plant + filters + mixing + FT gradient + Statement 3.

Written from the equations of ``docs/paper004.md`` only -- it imports nothing from the project --
and solved as ONE ODE with scipy's ``solve_ivp`` (Radau, rtol 1e-10, atol 1e-12).  The tests
compare the observer block and the co-simulated FMUs against it.

Monolithic state: plant ``x``; filters ``zeta`` (q), ``Omega`` (q x p), ``Phi`` (q x q); per
filter rate ``a_i`` (k = l + q + p of them) ``phi_f`` (l + q), ``c_f``, ``r``, ``E`` (q),
``P`` (p); the gradient estimate ``theta`` (l + p) and ``log nu``; the observer ``chi_hat`` (q).

* filters: ``zeta' = F zeta + g``, ``Omega' = F Omega + Psi``, ``Phi' = F Phi`` (``Phi(0) = I``)
  with ``F = Lambda(y, u)``, ``g = w`` (Statement 1) or ``F = Lambda - L C``, ``g = w + L y``
  (Statement 2); ``phi_f' = a (phi - phi_f)``, ``c_f' = a (c - c_f)``,
  ``r' = -a r + phi_fchi^T (Lambda zeta + w)``, ``E' = -a E - (phi_fchi^T Lambda Phi)^T``,
  ``P' = -a P - (phi_fchi^T (Lambda Omega + Psi))^T``;
* extended regression (unknowns ``theta_l, chi(t), e(0), theta_p``): rows
  ``[phi_fl, phi_fchi, E, P] = c_f + r`` for each ``a_i`` and ``[0, I, -Phi, -Omega] = zeta``;
  rows divided by their norms, ``Delta = det``, ``Y`` by Cramer's rule;
* ``theta' = gamma Delta (Y_theta - Delta theta)``, ``(log nu)' = -gamma Delta^2``,
  ``theta* = (theta - nu_c theta(0)) / (1 - nu_c)``, ``nu_c = min(nu, mu)``;
* ``chi_hat' = Lambda chi_hat + Psi theta*_p + w + gamma_x Delta (Y_chi - Delta chi_hat)``,
  ``x_hat = phi_L(chi_hat, theta*)``.

Plants: the pendulum ``phi'' = -a sin(phi) - b phi' + u`` (``chi = (phi, phi' + b phi)``,
``theta_p = (b, a)``) and the chemostat ``X' = mu(S) X - D X``,
``S' = -k mu(S) X + D (S_in - S)`` (``chi = (X, S)``, ``theta_p = S_in``).

Run as a script to print the convergence numbers quoted in ``docs/paper004.md``, or with
``--write-csv`` to regenerate the scenario reference files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

# ----------------------------------------------------------------------------- the two examples
MU_MAX, K_S, YIELD = 0.5, 1.0, 2.0   # chemostat's known constants (1/h, g/L, g/g)


def _monod(S):
    return MU_MAX * S / (K_S + S)


@dataclass
class Example:
    """One plant in its state-affine form; ``F``/``Linj`` given for Statement 2."""

    name: str
    q: int
    p: int
    l: int
    plant: callable        # (x, u, true) -> x'
    output: callable       # x -> y (scalar)
    Lambda: callable       # (y, u) -> q x q
    Psi: callable          # (y, u) -> q x p
    w: callable            # (y, u) -> q
    phi: callable          # (y, u) -> l + q
    c: callable            # (y, u) -> float
    phi_L: callable        # (chi, theta) -> x
    F: np.ndarray | None = None
    Linj: np.ndarray | None = None


def pendulum(omega_L: float) -> Example:
    """Pendulum, Statement 2 with ``Lambda_L = [[0, 1], [-omega_L^2, 0]]`` (``L = (0, omega_L^2)``)."""
    Linj = np.array([0.0, omega_L ** 2])
    return Example(
        name="pendulum", q=2, p=2, l=0,
        plant=lambda x, u, true: np.array([x[1], -true["a"] * math.sin(x[0]) - true["b"] * x[1] + u]),
        output=lambda x: x[0],
        Lambda=lambda y, u: np.array([[0.0, 1.0], [0.0, 0.0]]),
        Psi=lambda y, u: np.array([[-y, 0.0], [0.0, -math.sin(y)]]),
        w=lambda y, u: np.array([0.0, u]),
        phi=lambda y, u: np.array([1.0, 0.0]),
        c=lambda y, u: y,
        phi_L=lambda chi, th: np.array([chi[0], chi[1] - th[0] * chi[0]]),
        F=np.array([[0.0, 1.0], [-omega_L ** 2, 0.0]]), Linj=Linj)


def chemostat() -> Example:
    """Chemostat with Monod kinetics, Statement 1 (``F = Lambda(y, u)``)."""
    def plant(x, u, true):
        growth = _monod(x[1]) * x[0]
        return np.array([growth - u * x[0], -YIELD * growth + u * (true["S_in"] - x[1])])
    return Example(
        name="chemostat", q=2, p=1, l=0, plant=plant, output=lambda x: x[1],
        Lambda=lambda y, u: np.array([[_monod(y) - u, 0.0], [-YIELD * _monod(y), -u]]),
        Psi=lambda y, u: np.array([[0.0], [u]]),
        w=lambda y, u: np.zeros(2),
        phi=lambda y, u: np.array([0.0, 1.0]),
        c=lambda y, u: y,
        phi_L=lambda chi, th: np.array(chi, dtype=float))


def sines(offset=0.0, amplitude=(), omega=()):
    """``u(t) = offset + sum amplitude_i sin(omega_i t)``."""
    amplitude, omega = np.asarray(amplitude, float), np.asarray(omega, float)
    return lambda t: offset + float(np.sum(amplitude * np.sin(omega * t)))


# ----------------------------------------------------------------------------- the monolithic ODE
def _mix(A, Y):
    norms = np.linalg.norm(A, axis=1)
    norms = np.where(norms > 0, norms, 1.0)
    A, Y = A / norms[:, None], Y / norms
    n = A.shape[0]
    cramer = []
    for i in range(n):
        B = A.copy()
        B[:, i] = Y
        cramer.append(np.linalg.det(B))
    return np.array(cramer), float(np.linalg.det(A))


class Monolithic:
    """Plant + observer of paper 004 as one ODE (see module docstring)."""

    def __init__(self, ex: Example, true: dict, rates, gamma, gamma_x, mu=0.98, theta0=None, chi_hat0=None):
        self.ex, self.true = ex, true
        self.rates = np.asarray(rates, float)
        self.gamma, self.gamma_x, self.mu = gamma, gamma_x, mu
        q, p, l, k = ex.q, ex.p, ex.l, len(self.rates)
        assert k == l + q + p
        self.N = l + 2 * q + p
        self.theta0 = np.zeros(l + p) if theta0 is None else np.asarray(theta0, float)
        self.chi_hat0 = np.zeros(q) if chi_hat0 is None else np.asarray(chi_hat0, float)
        self.sizes = [2, q, q * p, q * q, k * (l + q), k, k, k * q, k * p, l + p, 1, q]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])

    def unpack(self, s):
        ex, k = self.ex, len(self.rates)
        parts = [s[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        x, zeta, Om, Ph, pf, cf, r, E, P, th, lnu, ch = parts
        return (x, zeta, Om.reshape(ex.q, ex.p), Ph.reshape(ex.q, ex.q), pf.reshape(k, ex.l + ex.q), cf, r,
                E.reshape(k, ex.q), P.reshape(k, ex.p), th, lnu[0], ch)

    def regression(self, zeta, Om, Ph, pf, cf, r, E, P):
        ex, k, N, q, l = self.ex, len(self.rates), self.N, self.ex.q, self.ex.l
        A, Y = np.zeros((N, N)), np.zeros(N)
        A[:k, :l + q] = pf
        A[:k, l + q:l + 2 * q] = E
        A[:k, l + 2 * q:] = P
        Y[:k] = cf + r
        A[k:, l:l + q] = np.eye(q)
        A[k:, l + q:l + 2 * q] = -Ph
        A[k:, l + 2 * q:] = -Om
        Y[k:] = zeta
        return _mix(A, Y)

    def theta_star(self, th, lnu):
        nu_c = min(math.exp(lnu), self.mu)
        return (th - nu_c * self.theta0) / (1.0 - nu_c)

    def rhs(self, t, s, u_of):
        ex, a, l, q = self.ex, self.rates, self.ex.l, self.ex.q
        x, zeta, Om, Ph, pf, cf, r, E, P, th, lnu, ch = self.unpack(s)
        u = u_of(t)
        y = ex.output(x)
        Lam, Psi, w = ex.Lambda(y, u), ex.Psi(y, u), ex.w(y, u)
        F = Lam if ex.F is None else ex.F
        g = w if ex.F is None else w + ex.Linj * y
        pfc = pf[:, l:]
        d = [ex.plant(x, u, self.true), F @ zeta + g, F @ Om + Psi, F @ Ph,
             a[:, None] * (ex.phi(y, u) - pf), a * (ex.c(y, u) - cf),
             -a * r + pfc @ (Lam @ zeta + w), -a[:, None] * E - pfc @ (Lam @ Ph),
             -a[:, None] * P - pfc @ (Lam @ Om + Psi)]
        Ym, delta = self.regression(zeta, Om, Ph, pf, cf, r, E, P)
        Y_theta = np.concatenate([Ym[:l], Ym[l + 2 * q:]])
        theta = self.theta_star(th, lnu)
        d += [self.gamma * delta * (Y_theta - delta * th), [-self.gamma * delta * delta],
              Lam @ ch + Psi @ theta[l:] + w + self.gamma_x * delta * (Ym[l:l + q] - delta * ch)]
        return np.concatenate([np.ravel(v) for v in d])

    def simulate(self, x0, u_of, times, rtol=1e-10, atol=1e-12) -> dict[str, np.ndarray]:
        """Solve on ``[0, times[-1]]``; return ``x``, ``x_hat``, ``theta_hat``, ``chi_hat``, ``Delta``, ``nu``."""
        ex, k = self.ex, len(self.rates)
        s0 = np.concatenate([x0, np.zeros(ex.q + ex.q * ex.p), np.eye(ex.q).ravel(),
                             np.zeros(k * (ex.l + ex.q) + 2 * k + k * ex.q + k * ex.p), self.theta0, [0.0],
                             self.chi_hat0])
        times = np.asarray(times, float)
        sol = solve_ivp(self.rhs, (0.0, times[-1]), s0, method="Radau", t_eval=times, rtol=rtol, atol=atol,
                        args=(u_of,))
        if sol.status != 0:
            raise RuntimeError(f"reference solve failed: {sol.message}")
        out = {name: [] for name in ("x", "x_hat", "theta_hat", "chi_hat", "Delta", "nu")}
        for s in sol.y.T:
            x, zeta, Om, Ph, pf, cf, r, E, P, th, lnu, ch = self.unpack(s)
            theta = self.theta_star(th, lnu)
            out["x"].append(x)
            out["x_hat"].append(ex.phi_L(ch, theta))
            out["theta_hat"].append(theta)
            out["chi_hat"].append(ch)
            out["Delta"].append(self.regression(zeta, Om, Ph, pf, cf, r, E, P)[1])
            out["nu"].append(math.exp(lnu))
        result = {key: np.array(value) for key, value in out.items()}
        result["time"] = times
        return result


# ----------------------------------------------------------------------------- scenario settings
#: the defaults of the two scenarios (kept equal to fmus/scenarios/state_affine_*; the tests check it)
PENDULUM = dict(true=dict(a=9.81, b=0.5), x0=[0.5, 0.0], omega_L=2.0, rates=[0.5, 2.0, 8.0, 32.0],
                gamma=1e10, gamma_x=1e10, u=dict(amplitude=[3.0, 4.0], omega=[1.3, 4.7]))
CHEMOSTAT = dict(true=dict(S_in=10.0), x0=[2.0, 3.0], rates=[0.2, 1.0, 5.0], gamma=1e7, gamma_x=1e7,
                 u=dict(offset=0.25, amplitude=[0.1, 0.05], omega=[0.5, 1.3]))


def run_pendulum(times, settings=PENDULUM, **changes):
    cfg = {**settings, **changes}
    model = Monolithic(pendulum(cfg["omega_L"]), cfg["true"], cfg["rates"], cfg["gamma"], cfg["gamma_x"])
    return model.simulate(np.asarray(cfg["x0"], float), sines(**cfg["u"]), times)


def run_chemostat(times, settings=CHEMOSTAT, **changes):
    cfg = {**settings, **changes}
    model = Monolithic(chemostat(), cfg["true"], cfg["rates"], cfg["gamma"], cfg["gamma_x"])
    return model.simulate(np.asarray(cfg["x0"], float), sines(**cfg["u"]), times)


@lru_cache(maxsize=None)
def cached(example: str, stop: float, dt: float, true: tuple = (), x0: tuple = ()) -> dict:
    """Reference on ``t = 0:dt:stop`` (computed once per session); ``true``/``x0`` override the defaults."""
    times = np.round(np.arange(int(round(stop / dt)) + 1) * dt, 12)
    settings = PENDULUM if example == "pendulum" else CHEMOSTAT
    changes = {}
    if true:
        changes["true"] = dict(true)
    if x0:
        changes["x0"] = list(x0)
    run = run_pendulum if example == "pendulum" else run_chemostat
    return run(times, settings, **changes)


def write_csv(result: dict, path: Path) -> None:
    """``time, x[1..], x_hat[1..], theta_hat[1..], Delta, nu`` (the scenario's reference file)."""
    columns = [result["time"][:, None], result["x"], result["x_hat"], result["theta_hat"],
               result["Delta"][:, None], result["nu"][:, None]]
    n, m = result["x"].shape[1], result["theta_hat"].shape[1]
    header = ",".join(["time"] + [f"x[{i + 1}]" for i in range(n)] + [f"x_hat[{i + 1}]" for i in range(n)]
                      + [f"theta_hat[{i + 1}]" for i in range(m)] + ["Delta", "nu"])
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=header, comments="", fmt="%.17g")


def _report(name, result, truth):
    t = result["time"]
    err_theta = np.abs(result["theta_hat"] - truth).max(axis=1)
    err_x = np.abs(result["x_hat"] - result["x"]).max(axis=1)
    below = lambda e, tol: t[np.nonzero(~(e < tol))[0][-1] + 1] if np.any(~(e < tol)) else t[0]  # noqa: E731
    switch = t[np.argmax(result["nu"] < 0.98)]
    print(f"{name}: nu < mu at {switch:.3f}; |theta - theta_hat| < 1e-4 from {below(err_theta, 1e-4):.3f}, "
          f"|x - x_hat| < 1e-4 from {below(err_x, 1e-4):.3f}; final errors {err_theta[-1]:.1e}, {err_x[-1]:.1e}")


if __name__ == "__main__":  # pragma: no cover - documentation numbers
    import sys
    root = Path(__file__).resolve().parent.parent
    pend = run_pendulum(np.linspace(0.0, 20.0, 2001))
    _report("pendulum", pend, [PENDULUM["true"]["b"], PENDULUM["true"]["a"]])
    chem = run_chemostat(np.linspace(0.0, 30.0, 3001))
    _report("chemostat", chem, [CHEMOSTAT["true"]["S_in"]])
    if "--write-csv" in sys.argv:
        write_csv(pend, root / "state_affine_pendulum" / "reference.csv")
        write_csv(chem, root / "state_affine_chemostat" / "reference.csv")
