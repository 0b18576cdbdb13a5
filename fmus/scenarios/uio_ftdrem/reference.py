"""Independent monolithic reference for paper 003: plant + UIO chain + filters + four FT-DREMs.

Written from the equations of the paper (and of ``docs/paper003.md`` where the paper is
inconsistent) -- it imports nothing from the project -- and solved as ONE ODE with scipy's
``solve_ivp`` (Radau, tight tolerances).  Only the paper's example structure is covered:
``n = 2``, relative degree ``r = 2``, ``theta = H xi``, ``Gamma = 0``, one sinusoid, ``xi0_1``
known (``theta_1 = 0``), unknowns of (17) ``[xi0_2, omega^2, omega^2 xi0_2]``.

Continuous-time laws (the co-simulated observer samples the same equations):

* plant (1) ``x' = A x + B (theta^T x + f)``, ``y = C x``;
* UIO (3)-(4): ``G = B / (C A B)``, ``M = A - G C A^2``, ``F = M - L C``; chain (7) for r = 2:
  ``z' = F z + (F^2 G + L) y``; ``Phi' = F Phi``, ``Phi(0) = I``;
* stage 1, (10): ``q1 = W1[y - C (z + F G y + G y')]`` (``C G = 0``: no ``y'``),
  ``m1 = W1[C Phi]``, ``W1 = l1/(p + l1)``;
* stage 2: ``W2 = l2^3/(p + l2)^3`` (order r + 1) in controllable canonical form (states
  ``w, w', w''``); ``z_bar = z + Phi x_tilde0_hat``;
  ``q = B_bar[(F - A) W2[z_bar] + (F^2 G + L) W2[y] + F G pW2[y] + G p^2W2[y] - A F G W2[y] - A G pW2[y]]``,
  ``s = H^T (W2[z_bar] + F G W2[y] + G pW2[y])`` (15); (17): ``W3 = l3^2/(p + l3)^2``,
  ``Y = p^2W3[q]``, ``phi = [p^2W3[s_2], -W3[q], W3[s_2]]``;
* stage 3: ``f_bar = q - s^T xi0_hat = a^T [sin w t, cos w t]`` (20),
  ``f_hat = Im((a_1 + j a_2) ((j w + l2)/l2)^3 e^{j w t})`` (23);
* stage 4 from ``t4``: ``x_hat' = (A + B theta_hat^T - K C) x_hat + B f_hat + K y``,
  ``Psi' = (A + B theta_hat^T - K C) Psi``, ``y - C x_hat = C Psi e0``, estimate ``x_hat + Psi e0_hat``;
* every FT-DREM (11)-(12): extension by ``a/(p + a)`` copies, ``Delta = det``,
  ``Y = adj(Phi_e) Y_e``, ``k' = gamma Delta (Y - Delta k)``, ``nu' = -gamma Delta^2 nu``,
  ``k* = (k - min(nu, mu) k(0)) / (1 - min(nu, mu))``, ``k(0) = 0``.

Stage 1 stops adapting when its own ``nu`` crosses ``mu``.  Stages 2-4 stop when the reference
itself finds them identified (``docs/paper003.md``, "when has it converged"), checked at the
communication points ``k * check_step`` as the co-simulated observer does: at the first check
time ``T`` at which the stage's FT-DREM has switched (``nu < mu``; stage 3 also needs stage 2
identified) and its estimate has stayed within ``tol (1 + max|ref|)`` of its value ``ref`` at
the start of the last ``window`` seconds (``ref`` is reset whenever it moves further or the stage
is not ready).  Stage 4 starts when stages 2 and 3 are identified.  (No timeout: the noise-free
example settles.)

How it is solved (what makes it fast):

* **piecewise between the switching times.**  The right-hand side is smooth except where some
  ``nu_k`` crosses ``mu`` (the kink of ``min(nu, mu)`` in ``k*``; stage 1 also stops there) and
  where a stage is identified or stage 4 starts.  Each piece is solved with the rhs of its own
  mode -- ``mu`` or ``nu`` in ``k*``, which stages adapt -- so no step ever straddles a kink: the
  crossings are found as events, the identifications on the check grid, and the solution is
  restarted there from a state integrated exactly up to the switching time.
* **little Python per call.**  The linear time-invariant block (plant, UIO, every filter of ``y``)
  is one matrix product; a single state (Radau's Newton iterations) is computed on Python floats
  (:meth:`Reference.rhs_one`), and the Jacobian by central differences on a stack of states in one
  vectorised call (:meth:`Reference.jacobian`).
* **nothing thrown away.**  A piece never runs past the earliest check time at which an
  identification test could pass.

Whole 20 s: ~55 s CPU (``docs/paper003.md``).

Run as a script to print the numbers of ``docs/paper003.md`` and (``--write``) the scenario's
reference CSV.
"""

from __future__ import annotations

import cmath
import math
import sys

import numpy as np
from scipy.integrate import solve_ivp

A = np.array([[0.0, 1.0], [-2.0, 0.0]])
B = np.array([0.0, 1.0])
C = np.array([2.0, 0.0])
H = np.eye(2)
B_BAR = np.array([1.0, 1.0])
POLES = (-0.5, -0.3)
PAPER = dict(x0=(-1.0, 1.0), xi0=(0.0, -1.0), amplitude=5.0, omega=1.0, phase=0.0)
TUNING = dict(z0=(-3.0, 3.0), lam=10.0, gamma=1e6, mu=0.98, rates1=(10.0,), rates2=(10.0, 5.0),
              rates3=(10.0,), rates4=(10.0,))
#: identification test of stages 2-4: tolerance, quiet window (s), check grid (the scenario's step)
SETTLING = dict(tol=1e-6, window=0.5, check_step=1e-3)
#: solver tolerances of the stored reference (see ``docs/paper003.md`` for the convergence check)
RTOL, ATOL = 1e-10, 1e-12


def design():
    """``G``, ``F``, ``L`` of (3)-(4) for the example (``L`` from the characteristic polynomial)."""
    G = B / (C @ A @ B)
    M = A - np.outer(G, C @ A @ A)
    L = place_output_gain(M, POLES)
    return G, M - np.outer(L, C), L


def place_output_gain(M, poles):
    """``L`` with ``det(sI - (M - L C)) = (s - p1)(s - p2)``: two linear equations in ``L``."""
    want = np.real(np.poly(poles))                       # [1, c1, c0]
    # det(sI - M + L C) = s^2 + (-tr M + C L) s + det(M - L C); both coefficients are affine in L
    def coefficients(L):
        K = M - np.outer(L, C)
        return np.array([-np.trace(K), np.linalg.det(K)])
    base = coefficients(np.zeros(2))
    J = np.column_stack([coefficients(np.eye(2)[i]) - base for i in range(2)])
    return np.linalg.solve(J, want[1:] - base)


def _canonical(order, lam):
    """Companion matrix of ``lam^k/(p + lam)^k`` with states ``(w, w', ..., w^(k-1))``."""
    coefficients = np.real(np.poly([-lam] * order))      # s^k + a_{k-1} s^{k-1} + ... + a_0
    Ac = np.zeros((order, order))
    Ac[:-1, 1:] = np.eye(order - 1)
    Ac[-1, :] = -coefficients[::-1][:-1]
    return Ac, lam ** order


def _filter(w, u, filt):
    """Companion filter on the last axis: ``(w', (W[u], pW[u], ..., p^k W[u]))`` for states ``w``
    and input ``u`` (any leading shape)."""
    Ac, gain = filt
    top = w @ Ac[-1] + gain * u                           # p^k W[u]
    derivative = np.concatenate([w[..., 1:], top[..., None]], axis=-1)
    return derivative, np.concatenate([w, top[..., None]], axis=-1)


class _Layout:
    """Named blocks of the flat state vector; :meth:`get` / :meth:`put` work on stacks of states
    (leading axes) and give each block its own shape."""

    def __init__(self, blocks):
        self.slices, self.shapes, start = {}, {}, 0
        for name, shape in blocks:
            size = int(np.prod(shape))
            self.slices[name], self.shapes[name] = slice(start, start + size), shape
            start += size
        self.size = start

    def __getitem__(self, name):
        return self.slices[name]

    def get(self, S, name):
        return S[..., self.slices[name]].reshape(S.shape[:-1] + self.shapes[name])

    def put(self, D, name, value):
        D[..., self.slices[name]] = np.reshape(value, D.shape[:-1] + (-1,))


#: the state: first the linear time-invariant block (plant, UIO, every filter of y), then the estimators
LAYOUT = _Layout([
    ("x", (2,)), ("z", (2,)), ("Phi", (2, 2)),
    ("w1", (3,)), ("e1", (3,)),                                     # stage 1: W1 of q1, m1 (2); extension
    ("w2", (7, 3)),                                                 # W2 of y, z (2), Phi columns (4)
    ("w3", (3, 2, 2)),                                              # W3 of (q, s_2) per component of (15)
    ("k1", (2,)), ("nu1", ()),
    ("e2", (2, 4)), ("k2", (3,)), ("nu2", ()),                      # stage 2 extension (2 copies)
    ("e3", (3,)), ("k3", (2,)), ("nu3", ()),                        # stage 3
    ("xh", (2,)), ("Psi", (2, 2)), ("e4", (3,)), ("k4", (2,)), ("nu4", ()),   # stage 4
])
N_LTI = LAYOUT["w3"].stop
#: linear read-outs of the LTI block: ``y``; per component of (15) (the part free of ``x_tilde(0)``, then
#: one per column of ``Phi``) the row ``[Y, phi]`` of (17) and ``q``, ``s`` of (15)
READOUTS = _Layout([("y", ()), ("row17", (3, 4)), ("q", (3,)), ("s", (3, 2))])
STAGES = (1, 2, 3, 4)


def _mix(Y_e, Phi_e):
    """``Delta = det(Phi_e)`` and ``adj(Phi_e) Y_e`` (Cramer's rule) for stacks ``(m, n)``, ``(m, n, n)``."""
    n = Y_e.shape[-1]
    matrices = np.repeat(Phi_e[:, None], n + 1, axis=1)  # copy 0: Phi_e; copy i: column i-1 replaced
    for i in range(n):
        matrices[:, i + 1, :, i] = Y_e
    determinants = np.linalg.det(matrices)
    return determinants[:, 0], determinants[:, 1:]


def _mix_one(Y_e, Phi_e):
    """:func:`_mix` for one ``Y_e`` (list) and ``Phi_e`` (list of rows), ``n`` = 2 or 3, on floats."""
    def det(rows):
        if len(rows) == 2:
            return rows[0][0] * rows[1][1] - rows[0][1] * rows[1][0]
        (a, b, c), (d, e, f), (g, h, i) = rows
        return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)

    n = len(Y_e)
    replaced = [[[Y_e[r] if col == i else Phi_e[r][col] for col in range(n)] for r in range(n)] for i in range(n)]
    return det(Phi_e), [det(rows) for rows in replaced]


class Reference:
    """The monolithic system for one plant case; :meth:`simulate` integrates it.

    Mode of the current piece: ``adapt[k]`` (stage ``k`` adapts), ``switched[k]`` (``nu_k < mu``
    passed: ``min(nu, mu) = nu``), ``stage4`` (stage 4 runs) and its gain ``K``.
    """

    def __init__(self, x0, xi0, amplitude, omega, phase, z0, lam, gamma, mu, rates1, rates2, rates3, rates4):
        self.x0, self.theta = np.array(x0, float), H @ np.array(xi0, float)
        self.amplitude, self.omega, self.phase = amplitude, omega, phase
        self.z0, self.lam, self.gamma, self.mu = np.array(z0, float), lam, gamma, mu
        self.rates = dict(zip(STAGES, (np.array(r, float) for r in (rates1, rates2, rates3, rates4))))
        self.G, self.F, self.L = design()
        self.L_tilde = self.F @ self.F @ self.G + self.L
        self.W1 = self.lam
        self.W2 = _canonical(3, lam)
        self.W3 = _canonical(2, lam)
        self.lti_matrix = self.lti_equations(np.eye(N_LTI))           # row i: the map of unit vector i
        self.adapt = dict.fromkeys(STAGES, True)
        self.switched = dict.fromkeys(STAGES, False)
        self.stage4 = False
        self.K = np.zeros(2)

    def initial_state(self):
        s = np.zeros(LAYOUT.size)
        s[LAYOUT["x"]] = self.x0
        s[LAYOUT["z"]] = self.z0
        s[LAYOUT["Phi"]] = np.eye(2).ravel()
        for stage in STAGES:
            s[LAYOUT[f"nu{stage}"]] = 1.0
        return s

    # -------------------------------------------------------------- pieces (stacks of states S: (m, size))
    def f(self, t):
        return self.amplitude * np.sin(self.omega * t + self.phase)

    def estimate(self, S, stage):
        """``k*`` of (12) with ``k(0) = 0``: ``k / (1 - min(nu, mu))``, the min taken by the mode."""
        nu_c = LAYOUT.get(S, f"nu{stage}") if self.switched[stage] else self.mu
        return LAYOUT.get(S, f"k{stage}") / (1.0 - np.asarray(nu_c))[..., None]

    def xi0_hat(self, S):
        xi0_2 = self.estimate(S, 2)[:, 0]
        return np.column_stack([np.zeros_like(xi0_2), xi0_2])

    def omega_hat(self, S):
        return np.sqrt(np.abs(self.estimate(S, 2)[:, 1]))

    def f_hat(self, t, S):
        """(23) with the stage-3 amplitudes and the stage-2 frequency."""
        a = self.estimate(S, 3)
        w = self.omega_hat(S)
        return np.imag((a[:, 0] + 1j * a[:, 1]) * ((1j * w + self.lam) / self.lam) ** 3 * np.exp(1j * w * t))

    def stage2_signals(self, S, y):
        """``q``, ``s`` of (15) per component: ``[x_tilde0-free part, per column of Phi]``; shapes
        ``(m, 3)`` and ``(m, 3, 2)``.  They are combined with ``x_tilde0_hat`` by the caller."""
        w2 = LAYOUT.get(S, "w2")
        _, Y = _filter(w2[:, 0], y, self.W2)                       # W2[y], pW2[y], p^2W2[y], p^3W2[y]
        Wz = w2[:, 1:3, 0]
        WPhi = w2[:, 3:7, 0].reshape(-1, 2, 2)                     # row j: W2[Phi e_j]
        FG, G = self.F @ self.G, self.G
        q0 = (Wz @ (self.F - A).T + np.outer(Y[:, 0], self.L_tilde - A @ FG) + np.outer(Y[:, 1], FG - A @ G)
              + np.outer(Y[:, 2], G)) @ B_BAR
        s0 = (Wz + np.outer(Y[:, 0], FG) + np.outer(Y[:, 1], G)) @ H
        qj = WPhi @ ((self.F - A).T @ B_BAR)
        sj = WPhi @ H
        return np.column_stack([q0, qj]), np.concatenate([s0[:, None], sj], axis=1)

    def lti_equations(self, S):
        """The linear time-invariant block for stacks of states ``S`` (m, N_LTI): its derivative
        without the disturbance ``B f(t)``, then the :data:`READOUTS`.  Both are linear in ``S``:
        :meth:`rhs` uses the matrix of this map, built once from the unit vectors."""
        get, put = LAYOUT.get, LAYOUT.put
        D = np.zeros_like(S)
        x, z, Phi = get(S, "x"), get(S, "z"), get(S, "Phi")
        y = x @ C
        put(D, "x", x @ A.T + np.outer(x @ self.theta, B))                                   # (1)
        put(D, "z", z @ self.F.T + np.outer(y, self.L_tilde))                              # (7)
        put(D, "Phi", self.F @ Phi)
        # stage 1, (10): C G = 0, y' is multiplied by zero
        y_dot = x @ (C @ A)
        q1_raw = y - z @ C - (C @ self.F @ self.G) * y - (C @ self.G) * y_dot
        w1, e1 = get(S, "w1"), get(S, "e1")
        put(D, "w1", self.W1 * (np.column_stack([q1_raw, C @ Phi]) - w1))
        put(D, "e1", self.rates[1][0] * (w1 - e1))
        # stage 2, (14)-(17): W2 of y, z and the columns of Phi; W3 of each component of (15)
        inputs2 = np.column_stack([y, z, Phi[:, :, 0], Phi[:, :, 1]])
        put(D, "w2", _filter(get(S, "w2"), inputs2, self.W2)[0])
        q, s = self.stage2_signals(S, y)
        d_w3, W3 = _filter(get(S, "w3"), np.stack([q, s[:, :, 1]], axis=-1), self.W3)   # (q, s_2) x (W3, pW3, p^2W3)
        put(D, "w3", d_w3)
        row17 = np.stack([W3[:, :, 0, 2], W3[:, :, 1, 2], -W3[:, :, 0, 0], W3[:, :, 1, 0]], axis=-1)
        return np.column_stack([D[:, :N_LTI], y, row17.reshape(-1, 12), q, s.reshape(-1, 6)])

    def rhs(self, t, s):
        """``ds/dt`` for ``solve_ivp(..., vectorized=True)``: ``s`` is ``(size,)`` or ``(size, m)``.

        Stacks are computed here (:meth:`jacobian`); a single state (the solver's Newton iterations)
        goes to :meth:`rhs_one`, the same equations on Python floats.
        """
        if s.ndim == 1 or s.shape[1] == 1:
            d = self.rhs_one(t, s.ravel())
            return d if s.ndim == 1 else d[:, None]
        return self.rhs_stack(t, s)

    def jacobian(self, t, s):
        """``d rhs / ds`` by central differences, all columns in one call of :meth:`rhs_stack` (one
        implementation for every column: rounding differences between :meth:`rhs_one` and
        :meth:`rhs_stack`, amplified by ``gamma`` and divided by the increment, would spoil it)."""
        h = 1e-6 * np.maximum(np.abs(s), 1e-6)
        columns = self.rhs_stack(t, np.column_stack([s[:, None] + np.diag(h), s[:, None] - np.diag(h)]))
        return (columns[:, :s.size] - columns[:, s.size:]) / (2.0 * h)

    def rhs_stack(self, t, s):
        """:meth:`rhs` for a stack of states ``s`` ``(size, m)``."""
        S = np.atleast_2d(s.T)
        D = np.zeros_like(S)
        get, put = LAYOUT.get, LAYOUT.put
        lti = S[:, :N_LTI] @ self.lti_matrix
        D[:, :N_LTI] = lti[:, :N_LTI]
        D[:, LAYOUT["x"]] += self.f(t) * B                                                   # (1)
        readouts = lti[:, N_LTI:]
        y = READOUTS.get(readouts, "y")

        # stage 1, (10)-(12)
        w1, e1 = get(S, "w1"), get(S, "e1")
        self._ft_drem(D, S, 1, np.column_stack([w1[:, 0], e1[:, 0]]), np.stack([w1[:, 1:], e1[:, 1:]], axis=1))

        # stage 2, (17)-(19): the components combined with x_tilde0_hat (linear in x_tilde(0))
        weights = np.column_stack([np.ones_like(y), self.estimate(S, 1)])
        row = np.einsum("mc,mcj->mj", weights, READOUTS.get(readouts, "row17"))            # [Y, phi] of (17)
        e2 = get(S, "e2")
        put(D, "e2", self.rates[2][:, None] * (row[:, None, :] - e2))
        self._ft_drem(D, S, 2, np.column_stack([row[:, 0], e2[:, :, 0]]),
                      np.concatenate([row[:, None, 1:], e2[:, :, 1:]], axis=1))

        # stage 3, (20)-(22)
        q = np.einsum("mc,mc->m", weights, READOUTS.get(readouts, "q"))
        s_vec = np.einsum("mc,mck->mk", weights, READOUTS.get(readouts, "s"))
        f_bar = q - np.einsum("mk,mk->m", s_vec, self.xi0_hat(S))
        w = self.omega_hat(S)
        phi3 = np.column_stack([np.sin(w * t), np.cos(w * t)])
        e3 = get(S, "e3")
        put(D, "e3", self.rates[3][0] * (np.column_stack([f_bar, phi3]) - e3))
        self._ft_drem(D, S, 3, np.column_stack([f_bar, e3[:, 0]]), np.stack([phi3, e3[:, 1:]], axis=1))

        # stage 4: observer of the identified plant + FT-DREM on its initial error
        if self.stage4:
            theta_hat = self.xi0_hat(S) @ H.T
            A_K = A + B[:, None] * theta_hat[:, None, :] - np.outer(self.K, C)      # (m, 2, 2)
            xh, Psi = get(S, "xh"), get(S, "Psi")
            put(D, "xh", np.einsum("mij,mj->mi", A_K, xh) + np.outer(self.f_hat(t, S), B) + np.outer(y, self.K))
            put(D, "Psi", A_K @ Psi)
            raw4 = np.column_stack([y - xh @ C, C @ Psi])
            e4 = get(S, "e4")
            put(D, "e4", self.rates[4][0] * (raw4 - e4))
            self._ft_drem(D, S, 4, np.column_stack([raw4[:, 0], e4[:, 0]]),
                          np.stack([raw4[:, 1:], e4[:, 1:]], axis=1))
        return D.T

    def rhs_one(self, t, s):
        """:meth:`rhs` for one state, on Python floats (numpy's per-call cost dominates at these sizes)."""
        lti = s[:N_LTI] @ self.lti_matrix
        d = np.zeros(LAYOUT.size)
        d[:N_LTI] = lti[:N_LTI]
        d[LAYOUT["x"]] += self.f(t) * B                                                      # (1)
        readouts, v = lti[N_LTI:].tolist(), s.tolist()
        y = readouts[READOUTS["y"]][0]
        at = {name: v[LAYOUT[name]] for name in LAYOUT.slices}
        estimate = {stage: [k / (1.0 - (at[f"nu{stage}"][0] if self.switched[stage] else self.mu))
                            for k in at[f"k{stage}"]] for stage in STAGES}
        gamma, out = self.gamma, {}

        def ft_drem(stage, Y_e, Phi_e):                                                    # (11)-(12)
            if not self.adapt[stage]:
                return
            delta, mixed = _mix_one(Y_e, Phi_e)
            out[f"k{stage}"] = [gamma * delta * (m - delta * k) for m, k in zip(mixed, at[f"k{stage}"])]
            out[f"nu{stage}"] = [-gamma * delta * delta * at[f"nu{stage}"][0]]

        # stage 1, (10)-(12)
        w1, e1 = at["w1"], at["e1"]
        ft_drem(1, [w1[0], e1[0]], [w1[1:], e1[1:]])
        # stage 2, (17)-(19)
        weights = [1.0] + estimate[1]
        rows17 = readouts[READOUTS["row17"]]
        row = [sum(w * rows17[4 * c + j] for c, w in enumerate(weights)) for j in range(4)]
        e2 = at["e2"]
        rates2 = self.rates[2].tolist()
        out["e2"] = [rates2[i] * (row[j] - e2[4 * i + j]) for i in range(2) for j in range(4)]
        ft_drem(2, [row[0], e2[0], e2[4]], [row[1:], e2[1:4], e2[5:8]])
        # stage 3, (20)-(22)
        q_all, s_all = readouts[READOUTS["q"]], readouts[READOUTS["s"]]
        q = sum(w * q_all[c] for c, w in enumerate(weights))
        s_2 = sum(w * s_all[2 * c + 1] for c, w in enumerate(weights))      # xi0_hat = [0, xi0_2]
        xi0_2, omega_hat = estimate[2][0], abs(estimate[2][1]) ** 0.5
        f_bar = q - s_2 * xi0_2
        phi3 = [math.sin(omega_hat * t), math.cos(omega_hat * t)]
        e3, rate3 = at["e3"], float(self.rates[3][0])
        out["e3"] = [rate3 * (value - e) for value, e in zip([f_bar] + phi3, e3)]
        ft_drem(3, [f_bar, e3[0]], [phi3, e3[1:]])
        # stage 4
        if self.stage4:
            a1, a2 = estimate[3]
            f_hat = ((a1 + 1j * a2) * ((1j * omega_hat + self.lam) / self.lam) ** 3
                     * cmath.exp(1j * omega_hat * t)).imag                                    # (23)
            A_K = (A + np.outer(B, H @ [0.0, xi0_2]) - np.outer(self.K, C)).tolist()
            xh, Psi, e4 = at["xh"], at["Psi"], at["e4"]
            K, c = self.K.tolist(), C.tolist()
            out["xh"] = [A_K[i][0] * xh[0] + A_K[i][1] * xh[1] + float(B[i]) * f_hat + K[i] * y for i in range(2)]
            out["Psi"] = [A_K[i][0] * Psi[j] + A_K[i][1] * Psi[2 + j] for i in range(2) for j in range(2)]
            raw4 = [y - c[0] * xh[0] - c[1] * xh[1]] + [c[0] * Psi[j] + c[1] * Psi[2 + j] for j in range(2)]
            rate4 = float(self.rates[4][0])
            out["e4"] = [rate4 * (value - e) for value, e in zip(raw4, e4)]
            ft_drem(4, [raw4[0], e4[0]], [raw4[1:], e4[1:]])
        for name, value in out.items():
            d[LAYOUT[name]] = value
        return d

    def _ft_drem(self, D, S, stage, Y_e, Phi_e):
        """(11)-(12) of one stage: ``k' = gamma Delta (Y - Delta k)``, ``nu' = -gamma Delta^2 nu``."""
        if not self.adapt[stage]:
            return
        delta, mixed = _mix(Y_e, Phi_e)
        k, nu = LAYOUT.get(S, f"k{stage}"), LAYOUT.get(S, f"nu{stage}")
        LAYOUT.put(D, f"k{stage}", self.gamma * delta[:, None] * (mixed - delta[:, None] * k))
        LAYOUT.put(D, f"nu{stage}", -self.gamma * delta * delta * nu)

    def x_hat(self, t, S):
        """Stage 4 estimate, or before it the derivative-free part ``z_bar + F G y`` of (8)."""
        if self.stage4:
            return LAYOUT.get(S, "xh") + np.einsum("mij,mj->mi", LAYOUT.get(S, "Psi"), self.estimate(S, 4))
        z_bar = LAYOUT.get(S, "z") + np.einsum("mij,mj->mi", LAYOUT.get(S, "Phi"), self.estimate(S, 1))
        return z_bar + np.outer(LAYOUT.get(S, "x") @ C, self.F @ self.G)

    def outputs(self, times, S):
        """The recorded quantities at ``times`` for the states ``S`` (one row per time)."""
        return dict(x=LAYOUT.get(S, "x"), x_tilde0_hat=self.estimate(S, 1), xi0_hat=self.xi0_hat(S),
                    omega_hat=self.omega_hat(S)[:, None], f_hat=self.f_hat(times, S)[:, None],
                    x_hat=self.x_hat(times, S))

    # -------------------------------------------------------------- integration
    def _switching_events(self):
        """Terminal events ``nu_k = mu`` of the FT-DREMs that adapt and have not switched yet."""
        events = []
        for stage in STAGES:
            if self.adapt[stage] and not self.switched[stage] and (stage < 4 or self.stage4):
                def event(t, s, name=f"nu{stage}"):
                    return s[LAYOUT[name]][0] - self.mu
                event.terminal, event.direction, event.stage = True, -1, stage
                events.append(event)
        return events

    def solve(self, t0, t1, s, rtol, atol, events=()):
        """One piece: Radau on ``[t0, t1]`` with the current mode, stopping at the first event."""
        solution = solve_ivp(self.rhs, (t0, t1), s, method="Radau", rtol=rtol, atol=atol, dense_output=True,
                             jac=self.jacobian, events=list(events) or None)
        if not solution.success:
            raise RuntimeError(solution.message)
        return solution

    def state_at(self, solution, T, rtol, atol):
        """The state at ``T`` inside ``solution``, integrated from the last step point before ``T``
        (not interpolated: the next piece starts from it)."""
        i = np.searchsorted(solution.t, T, side="right") - 1
        if solution.t[i] == T:
            return solution.y[:, i].copy()
        return self.solve(solution.t[i], T, solution.y[:, i], rtol, atol).y[:, -1].copy()

    def simulate(self, times, rtol=RTOL, atol=ATOL, tol=SETTLING["tol"], window=SETTLING["window"],
                 check_step=SETTLING["check_step"], chunk=1.0):
        """Outputs at ``times``: dict of arrays (``x``, ``x_tilde0_hat``, ``xi0_hat``, ``omega_hat``, ...)
        and ``stage_times`` (stages 2, 3 and 4 identified, found by the reference itself).

        Solved piece by piece (at most ``chunk`` seconds each, with dense output): a piece ends at
        the first switching event ``nu_k = mu`` or at the first check time at which the
        identification tests change the mode; the next piece starts from the state integrated
        exactly up to there.  A piece never runs past the earliest check time at which a test could
        pass (nothing is integrated in the wrong mode and thrown away).
        """
        times = np.asarray(times, dtype=float)
        s = self.initial_state()
        out = {name: np.empty((times.size, size)) for name, size in
               (("x", 2), ("x_tilde0_hat", 2), ("xi0_hat", 2), ("omega_hat", 1), ("f_hat", 1), ("x_hat", 2))}
        detectors = {2: _Settling(tol, window), 3: _Settling(tol, window)}
        found: dict[int, float] = {}

        def check(t, state) -> bool:
            """The identification tests at check time ``t``; True when the mode changes."""
            S = state[None]
            ready = {k: self.switched[k] for k in (2, 3, 4)}
            ready[3] = ready[3] and 2 in found
            changed = False
            for k, detector in detectors.items():
                if k not in found and detector.update(t, self.estimate(S, k)[0], ready[k]):
                    found[k] = t
                    changed = True
            if 2 in found and 3 in found and 4 not in detectors:
                detectors[4] = _Settling(tol, window, start=t)
                changed = True
            return changed

        t, end, k = 0.0, times[-1], 1
        while t < end:
            events = self._switching_events()
            horizon = min([t + chunk, end] + [k_next * check_step for k_next in
                                               (d.earliest(check_step) for d in detectors.values())
                                               if k_next * check_step > t])
            solution = self.solve(t, horizon, s, rtol, atol, events)
            t_stop = solution.t[-1]
            fired = [event.stage for event, t_event in zip(events, solution.t_events or []) if t_event.size]
            while k * check_step <= t_stop + 1e-12:
                T = k * check_step
                k += 1
                if check(T, solution.sol(T)):
                    t_stop, fired = T, []
                    break
            record = (times >= t) & (times <= t_stop)
            if record.any():
                for name, value in self.outputs(times[record], solution.sol(times[record]).T).items():
                    out[name][record] = value
            s = self.state_at(solution, t_stop, rtol, atol)
            t = t_stop
            for stage in fired:                                   # nu_k crossed mu; stage 1 stops there
                self.switched[stage] = True
                self.adapt[1] = self.adapt[1] and stage != 1
            for stage in (2, 3):
                if stage in found:
                    self.adapt[stage] = False
            if 4 in detectors and not self.stage4:
                self._start_stage4(s)
            if 4 in found:
                self.adapt[4] = False
        out["stage_times"] = np.array([found.get(k, np.nan) for k in (2, 3, 4)])
        return out

    def _start_stage4(self, s):
        theta = H @ self.xi0_hat(s[None])[0]
        self.K = place_output_gain(A + np.outer(B, theta), np.linalg.eigvals(self.F))
        s[LAYOUT["xh"]] = self.x_hat(0.0, s[None])[0]
        s[LAYOUT["Psi"]] = np.eye(2).ravel()
        self.stage4 = True


class _Settling:
    """The identification test of one stage (see the module docstring)."""

    def __init__(self, tol: float, window: float, start: float = 0.0):
        self.tol, self.window = tol, window
        self.reference, self.since = None, start

    def update(self, t: float, estimate, ready: bool) -> bool:
        """Feed the estimate at check time ``t``; True once the stage is identified."""
        estimate = np.array(estimate, dtype=float)
        moved = self.reference is None or \
            np.max(np.abs(estimate - self.reference)) > self.tol * (1.0 + np.max(np.abs(self.reference)))
        if not ready or moved:
            self.reference, self.since = estimate, t
            return False
        return t - self.since >= self.window

    def earliest(self, check_step: float) -> int:
        """Index ``k`` of the first check time ``k * check_step`` at which :meth:`update` could pass."""
        k = int(np.ceil((self.since + self.window) / check_step)) - 1
        while k * check_step - self.since < self.window:
            k += 1
        return k


def simulate(times, rtol=RTOL, atol=ATOL, **case):
    """Reference outputs at ``times`` for the paper's plant with ``case`` overrides; ``stage_times``
    holds the times at which the reference found stages 2, 3 and 4 identified."""
    parameters = {**PAPER, **TUNING, **case}
    return Reference(**parameters).simulate(times, rtol, atol)


COLUMNS = ["plant.x[1]", "plant.x[2]", "observer.x_tilde0_hat[1]", "observer.x_tilde0_hat[2]",
           "observer.xi0_hat[1]", "observer.xi0_hat[2]", "observer.omega_hat", "observer.f_hat",
           "observer.x_hat[1]", "observer.x_hat[2]"]


def write_csv(path, T=20.0, grid=0.01):
    times = np.round(np.arange(0.0, T + grid / 2, grid), 10)
    out = simulate(times)
    data = np.column_stack([times, out["x"], out["x_tilde0_hat"], out["xi0_hat"], out["omega_hat"], out["f_hat"],
                            out["x_hat"]])
    header = ",".join(["time"] + COLUMNS)
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.17g")
    return out["stage_times"]


def _main(argv):  # pragma: no cover - prints the numbers of the docs, writes the scenario reference
    import time
    if "--write" in argv:
        path = argv[argv.index("--write") + 1]
        start = time.process_time()
        stage_times = write_csv(path)
        print(f"wrote {path} in {time.process_time() - start:.1f} s CPU; stages 2, 3, 4 identified at {stage_times}")
        return
    times = np.round(np.arange(0.0, 20.0 + 1e-9, 0.01), 10)
    start = time.process_time()
    out = simulate(times)
    print(f"Radau reference, 20 s: {time.process_time() - start:.1f} s CPU")
    print("stages 2, 3, 4 identified at", out["stage_times"])
    last = times >= 16.0
    f_true = PAPER["amplitude"] * np.sin(PAPER["omega"] * times + PAPER["phase"])
    print("omega error last 20 %:", np.abs(out["omega_hat"][last, 0] - PAPER["omega"]).max())
    print("xi0 error last 20 %:", np.abs(out["xi0_hat"][last] - PAPER["xi0"]).max())
    print("f error last 20 %:", np.abs(out["f_hat"][last, 0] - f_true[last]).max())
    rel = np.linalg.norm(out["x_hat"] - out["x"], axis=1) / (1 + np.linalg.norm(out["x"], axis=1))
    print("x relative error last 20 %:", rel[last].max())


if __name__ == "__main__":  # pragma: no cover
    _main(sys.argv[1:])
