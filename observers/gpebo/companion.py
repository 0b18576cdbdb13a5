r"""Regression (16) for generators whose whole coefficient vector ``gamma`` is unknown.

Generators (1)-(2) in the observer companion form ``Gamma = Gamma0 + gamma e_1^T`` have the
characteristic polynomial ``z^d - gamma_1 z^(d-1) - ... - gamma_d``, so by Cayley-Hamilton every
output ``w`` of a generator of size ``d`` obeys the recurrence

.. math:: w(k+d) = \gamma_1 w(k+d-1) + \dots + \gamma_d w(k)        \qquad (\gamma_d \ne 0: \text{also backwards}).

For a generator declared ``"all"`` the ``d`` entries are unknowns; for ``"last"`` (the form of
:class:`~observers.gpebo.regression.ShiftRegression`, ``gamma = [0, ..., 0, g]``) only ``g`` is.

Input-output form (8) with ``T`` terms ``s_t(k + o_t) w_t(k + o_t)``
(:func:`~observers.gpebo.terms.io_terms`).  Unknowns: for each term ``d_t`` consecutive values
``q_t = [w_t(k + o_t + b_t), ..., w_t(k + o_t + b_t + d_t - 1)]`` with staggered starts
``b_t = d_1 + ... + d_(t-1)``; every other ``w_t(k + o_t + j)`` is ``a_(t,j)(gamma)^T q_t``, by the
recurrence forwards (a polynomial in ``gamma``) or backwards (a Laurent polynomial, dividing by
``gamma_d``).  The form (8) written at ``k, k+1, ..., k+R-1`` (``R = 1 + sum_t d_t`` rows) is
``M(k) [q; -1] = 0`` with ``M[j, (t, i)] = s_t(k + o_t + j) a_(t,j,i)(gamma)`` and last column
``y(k + n + j)``, so ``det M = 0`` (the mixing step (14)-(15)).

Leibniz: every permutation gives a product of data times a Laurent polynomial of ``gamma``; the
permutations with the same product of data are merged, ``det M = sum_q P_q(k) pi_q(gamma) = 0``.
(Grouping by the data products, not by the monomials of ``gamma``, is what keeps it small: the
paper's structure with both generators of size 2 fully unknown has 68 monomials but 30 products.)
The staggering makes the diagonal matching the product ``P_q0`` of data whose coefficient is
``pi_q0 = +-1``: dividing by it assumes nothing, and

.. math:: \zeta = P_{q_0} = \rho^T \sigma, \qquad \rho = -[P_q]_{q \ne q_0},
          \qquad \sigma = [\pi_q / \pi_{q_0}]_{q \ne q_0},

realisable ``n + R - 1`` samples late (``window = n + R``).  Stage 1's left inverse ``sigma^L``:
each unknown is one entry of ``sigma`` that is a single monomial ``c x_v`` (divided by ``c``), else a
ratio of two single-monomial entries (the denominator's unknowns then must be nonzero), else a
product of two; see :attr:`CompanionRegression.recovery`.

Limits (precise, refused naming the field): at most :attr:`MAX_ROWS` rows ``R`` (the Leibniz sum has
``R!`` permutations) and at most :attr:`MAX_UNKNOWNS` unknowns ``p`` in ``sigma``.  Measured in
``docs/adaptive-gpebo.md``.
"""

from __future__ import annotations

from collections import defaultdict
from itertools import permutations

import numpy as np

from obsfmu.observers.checks import ParameterError

from . import laurent
from .model import GeneratorModel
from .terms import GENERATORS, io_terms

__all__ = ["CompanionRegression", "UNKNOWN_FORMS"]

UNKNOWN_FORMS = ("last", "all")   #: per generator: only g of [0, ..., 0, g] unknown, or the whole gamma


def _variables(sizes, unknown) -> tuple[list[list], list[str]]:
    """Per generator the index of each gamma entry among the unknowns (None: a known 0), and their names."""
    slots, names = [], []
    for v, size in enumerate(sizes):
        if unknown[v] == "all":
            slots.append(list(range(len(names), len(names) + size)))
            names += [f"{GENERATORS[v]}[{i + 1}]" for i in range(size)]
        elif size:
            slots.append([None] * (size - 1) + [len(names)])
            names.append(GENERATORS[v])
        else:
            slots.append([])
    return slots, names


def shifted_value(slot: list, shift: int, variables: int) -> list:
    """``w(shift)`` of a generator with unknown entries ``slot`` as Laurent coefficients on ``w(0 .. d-1)``."""
    d, memo = len(slot), {}

    def w(j: int) -> list:
        if j not in memo:
            if 0 <= j < d:
                memo[j] = [laurent.constant(1.0 if c == j else 0.0, variables) for c in range(d)]
            elif j >= d:       # w(j) = gamma_1 w(j-1) + ... + gamma_d w(j-d)
                memo[j] = _combination(slot, [w(j - i) for i in range(1, d + 1)], d, variables)
            else:              # w(j) = (w(j+d) - gamma_1 w(j+d-1) - ... - gamma_(d-1) w(j+1)) / gamma_d
                rest = _combination(slot[:-1], [w(j + d - i) for i in range(1, d)], d, variables)
                inverse = laurent.variable(slot[-1], variables, -1)
                memo[j] = [laurent.multiply(inverse, laurent.add(a, b, -1.0)) for a, b in zip(w(j + d), rest)]
        return memo[j]

    return w(shift)


def _combination(slot: list, values: list, d: int, variables: int) -> list:
    """``sum_i gamma_i values[i-1]`` over the unknown (non-None) entries of ``slot``."""
    total = [{} for _ in range(d)]
    for index, value in zip(slot, values):
        if index is not None:
            total = [laurent.add(a, laurent.multiply(laurent.variable(index, variables), b))
                     for a, b in zip(total, value)]
    return total


class CompanionRegression:
    """Regression (16) with the whole ``gamma`` of chosen generators unknown (module docstring).

    Same interface as :class:`~observers.gpebo.regression.ShiftRegression`.

    Parameters
    ----------
    model : GeneratorModel
    unknown : sequence of "last" | "all", one per generator (beta, theta, delta)
    """

    MAX_ROWS = 7
    MAX_UNKNOWNS = 50     #: measured: beyond ~50 normalised rows DREM's |Delta| falls below round-off (docs)
    MAX_TERMS = 6

    def __init__(self, model: GeneratorModel, unknown):
        self.model, self.unknown = model, tuple(unknown) + ("last",) * (len(GENERATORS) - len(unknown))
        if len(self.unknown) != len(GENERATORS) or any(form not in UNKNOWN_FORMS for form in self.unknown):
            raise ParameterError(f"gamma_unknown: expected at most {len(GENERATORS)} of {UNKNOWN_FORMS} (beta, theta, "
                                 f"delta), got {list(unknown)}")
        self.slots, names = _variables(model.sizes, self.unknown)
        self.names = tuple(names)
        self.terms = io_terms(model, self.MAX_TERMS)
        self.field = next((f"{GENERATORS[v]}_unknown" for v, form in enumerate(self.unknown) if form == "all"),
                          "gamma_unknown")     #: the field a limit's refusal names
        sizes = [model.sizes[v] for v, _, _ in self.terms]
        self.R = 1 + sum(sizes)
        if self.R > self.MAX_ROWS:
            raise ParameterError(f"{self.field}: with a whole gamma unknown the regression's matrix has "
                                 f"R = 1 + sum of the term sizes {sizes} = {self.R} rows; at most {self.MAX_ROWS} are "
                                 "supported (R! permutations): use smaller generators or fewer terms")
        self.window = model.n + self.R
        groups = self._leibniz()
        self._choose_normaliser(groups)
        if self.p > self.MAX_UNKNOWNS:
            raise ParameterError(f"{self.field}: the full-gamma regression has {self.p} unknowns; at "
                                 f"most {self.MAX_UNKNOWNS} are supported (DREM's Delta of that many rows falls below round-off): "
                                 "use smaller generators, fewer terms or \"last\" for a generator")
        self._recoveries()

    # ------------------------------------------------------------------ building
    def _columns(self) -> list[tuple[int, int, int]]:
        """``(term t, entry i, start b_t)`` per column of ``M`` (the ``y`` column is the last)."""
        columns, start = [], 0
        for t, (v, _, _) in enumerate(self.terms):
            d = self.model.sizes[v]
            columns += [(t, i, start) for i in range(d)]
            start += d
        return columns

    def _entries(self) -> list[list]:
        """``M[j][c] = (factor, polynomial)``: factor ``(signal, sample index)`` (None for 1)."""
        nv, n = len(self.names), self.model.n
        M = []
        for j in range(self.R):
            row = []
            for t, i, start in self._columns():
                v, signal, offset = self.terms[t]
                polynomial = shifted_value(self.slots[v], j - start, nv)[i]
                row.append((None if signal == "1" else (signal, offset + j), polynomial))
            row.append((("y", n + j), laurent.constant(1.0, nv)))
            M.append(row)
        return M

    def _leibniz(self) -> dict:
        """``det M`` as ``{sorted data factors: pi_q(gamma)}`` (permutations with one product merged)."""
        M, groups = self._entries(), defaultdict(dict)
        for permutation in permutations(range(self.R)):
            chosen = [M[j][c] for j, c in enumerate(permutation)]
            if any(not polynomial for _, polynomial in chosen):
                continue
            sign = round(np.linalg.det(np.eye(self.R)[list(permutation)]))
            polynomial = laurent.constant(float(sign), len(self.names))
            for _, entry in chosen:
                polynomial = laurent.multiply(polynomial, entry)
            key = tuple(sorted((factor for factor, _ in chosen if factor is not None), key=repr))
            groups[key] = laurent.add(groups[key], polynomial)
        return {key: polynomial for key, polynomial in groups.items() if polynomial}

    def _choose_normaliser(self, groups: dict) -> None:
        """``q0``: the product whose coefficient is one monomial, the constant if there is one (staggering)."""
        keys = list(groups)
        single = [q for q in keys if len(groups[q]) == 1]
        if not single:
            raise ParameterError(f"{self.field}: no product of data in the full-gamma determinant has a "
                                 "single monomial as coefficient to normalise by")
        q0 = min(single, key=lambda q: sum(abs(e) for e in next(iter(groups[q]))))
        (exponent0, c0), = groups[q0].items()
        inverse = {tuple(-e for e in exponent0): 1.0 / c0}
        self.zeta_key = q0
        self.rho_keys = [q for q in keys if q != q0]
        self.sigma_polynomials = [laurent.multiply(inverse, groups[q]) for q in self.rho_keys]
        self.p = len(self.rho_keys)
        divisors = {v for v, e in enumerate(exponent0) if e > 0}
        divisors |= {v for s in self.sigma_polynomials for e in s for v, power in enumerate(e) if power < 0}
        self._divisor_set = divisors
        self._index_table()

    def _index_table(self) -> None:
        """Row ``q`` of ``self._index``: where the factors of ``P_q`` are in the data vector of :meth:`row`."""
        w, n = self.window, self.model.n
        position = {"u": 0, "y": w}
        width = max(len(key) for key in [self.zeta_key] + self.rho_keys)
        one = (2 + n) * w     # the data vector's last entry is 1 (pads shorter products)

        def where(factor) -> int:
            signal, index = factor
            return position[signal] + index if signal in position else (2 + signal) * w + index

        self._index = np.full((1 + self.p, width), one)
        for q, key in enumerate([self.zeta_key] + self.rho_keys):
            self._index[q, :len(key)] = [where(factor) for factor in key]

    def _recoveries(self) -> None:
        """For every unknown ``x_v``: ``(a, scale)``, ``(a, b, "ratio", scale)`` or ``(a, b, "product", scale)``."""
        monomials = {a: next(iter(s.items())) for a, s in enumerate(self.sigma_polynomials) if len(s) == 1}
        self.recovery = []
        for v, name in enumerate(self.names):
            target = tuple(int(i == v) for i in range(len(self.names)))
            found = self._find(monomials, target)
            if found is None:
                raise ParameterError(f"{self.field}: no entry, ratio or product of two entries of sigma "
                                     f"of the full-gamma regression is {name}: it is not recoverable")
            self.recovery.append(found)
        for entry in self.recovery:
            if len(entry) == 4 and entry[2] == "ratio":
                self._divisor_set |= {v for v, e in enumerate(monomials[entry[1]][0]) if e}
        self.divisors = tuple(sorted(self._divisor_set))

    @staticmethod
    def _find(monomials: dict, target: tuple):
        for a, (e, c) in monomials.items():
            if e == target:
                return (a, 1.0 / c)
        for combine, sign in (("ratio", -1), ("product", 1)):
            for a, (ea, ca) in monomials.items():
                for b, (eb, cb) in monomials.items():
                    if tuple(x + sign * y for x, y in zip(ea, eb)) == target:
                        return (a, b, combine, cb / ca if combine == "ratio" else 1.0 / (ca * cb))
        return None

    # ------------------------------------------------------------------ the interface of ShiftRegression
    def sigma(self, *gammas) -> np.ndarray:
        """``sigma(gamma)``; the unknowns the regression divides by must be nonzero."""
        for v in self.divisors:
            if gammas[v] == 0:
                raise ParameterError(f"{self.names[v]}: must be nonzero (the regression is divided by it)")
        return np.array([laurent.evaluate(s, gammas) for s in self.sigma_polynomials])

    def gammas(self, sigma) -> np.ndarray:
        """Left inverse ``sigma^L`` (:attr:`recovery`); a zero denominator gives 0 (not yet excited)."""
        values = []
        for entry in self.recovery:
            if len(entry) == 2:
                values.append(entry[1] * sigma[entry[0]])
            elif entry[2] == "product":
                values.append(entry[3] * sigma[entry[0]] * sigma[entry[1]])
            else:
                values.append(entry[3] * sigma[entry[0]] / sigma[entry[1]] if sigma[entry[1]] != 0 else 0.0)
        return np.array(values, dtype=float)

    def full_coefficients(self, gammas) -> tuple[np.ndarray, ...]:
        """The generator vectors ``gamma_beta``, ``gamma_theta``, ``gamma_delta`` (known entries 0)."""
        return tuple(np.array([0.0 if i is None else float(gammas[i]) for i in slot]) for slot in self.slots)

    def unknowns(self, *vectors) -> np.ndarray:
        """The unknown entries of the generator vectors, in the order of :attr:`names`."""
        values = np.zeros(len(self.names))
        for slot, vector in zip(self.slots, vectors):
            for index, value in zip(slot, vector):
                if index is not None:
                    values[index] = float(value)
        return values

    def error_bound(self, sigma_hat, sigma_error) -> float:
        """Bound on ``max |gamma_hat - gamma|`` from ``|sigma_hat - sigma| <= sigma_error`` (entrywise)."""
        s, e, bounds = np.abs(sigma_hat), np.asarray(sigma_error), []
        for entry in self.recovery:
            a, scale = entry[0], abs(entry[-1])
            if len(entry) == 2:
                bounds.append(scale * e[a])
            elif entry[2] == "product":
                b = entry[1]
                bounds.append(scale * (s[a] * e[b] + s[b] * e[a] + e[a] * e[b]))
            else:           # |a/b - a_hat/b_hat| <= (|a_hat| e_b + |b_hat| e_a) / (|b_hat| (|b_hat| - e_b))
                b = entry[1]
                bounds.append(scale * (s[a] * e[b] + s[b] * e[a]) / (s[b] * (s[b] - e[b]))
                              if s[b] > e[b] else np.inf)
        return float(max(bounds))

    def row(self, u, y) -> tuple[float, np.ndarray]:
        """``(zeta(k), rho(k))`` from ``u``, ``y`` over the window (oldest first)."""
        f = np.array([self.model.nonlinearity(value) for value in y])     # shape (window, n)
        data = np.concatenate([np.asarray(u, dtype=float), np.asarray(y, dtype=float), f.T.ravel(), [1.0]])
        products = np.prod(data[self._index], axis=1)
        return float(products[0]), -products[1:]
