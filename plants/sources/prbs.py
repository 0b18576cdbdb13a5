"""Seeded pseudo-random binary sequences of maximal-length shift registers."""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import require_positive

from .base import PiecewiseConstant, integer_parameter, interval_index, scalar_parameter

__all__ = ["PRIMITIVE_TAPS", "PRBS"]


#: feedback taps of a maximal-length Fibonacci LFSR for each register length (Xilinx XAPP052):
#: ``a[k + n] = XOR of a[k + n - tap]`` over the taps, characteristic polynomial
#: ``x^n + sum_tap x^(n - tap)``, primitive over GF(2) (checked by the tests)
PRIMITIVE_TAPS = {
    2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
    11: (11, 9), 12: (12, 6, 4, 1), 13: (13, 4, 3, 1), 14: (14, 5, 3, 1), 15: (15, 14), 16: (16, 15, 13, 4),
    17: (17, 14), 18: (18, 11), 19: (19, 6, 2, 1), 20: (20, 17), 21: (21, 19), 22: (22, 21), 23: (23, 18),
    24: (24, 23, 22, 17), 25: (25, 22), 26: (26, 6, 2, 1), 27: (27, 5, 2, 1), 28: (28, 25), 29: (29, 27),
    30: (30, 6, 4, 1), 31: (31, 28), 32: (32, 22, 2, 1),
}


#: PRBS.value in C (Source.c_value): p = amplitude, bit_period, seed, n, polynomial, offset
_C_VALUE = """\
static uint64_t prbs_multiply(uint64_t a, uint64_t b, uint64_t polynomial, int n)   /* PRBS._multiply */
{
    uint64_t product = 0;
    for (; b; b >>= 1) {
        if (b & 1) product ^= a;
        a <<= 1;                                                 /* PRBS._times_x */
        if (a >> n & 1) a ^= polynomial;
    }
    return product;
}

static double source_value(double t, const double *p)
{
    const uint64_t seed = (uint64_t)p[2], polynomial = (uint64_t)p[4];
    const int n = (int)p[3];
    double index = floor(t / p[1] + 1e-09);                      /* interval_index */
    uint64_t k, result = 1, power = 2, bits;                     /* x^0, x^1 */
    int parity = 0;
    index = index != index ? 0.0 : index < 0.0 ? 0.0 : index > 0x1p62 ? 0x1p62 : index;
    for (k = (uint64_t)index; k; k >>= 1) {                      /* x^k mod p(x): PRBS.bit */
        if (k & 1) result = prbs_multiply(result, power, polynomial, n);
        power = prbs_multiply(power, power, polynomial, n);
    }
    for (bits = result & seed; bits; bits >>= 1) parity ^= (int)(bits & 1);
    return p[5] + p[0] * (2.0 * (double)parity - 1.0);
}"""


class PRBS(PiecewiseConstant):
    """Pseudo-random binary sequence of a maximal-length LFSR: ``y = offset + amplitude (2 a_k - 1)``
    on bit interval ``k`` (``[k bit_period, (k + 1) bit_period)``, negative times in bit 0).

    ``a_0 .. a_{n-1}`` are the bits of ``seed`` (``a_j = (seed >> j) & 1``, ``1 <= seed < 2^n``), and
    ``a_{k+n} = XOR_tap a_{k+n-tap}`` with the taps of :data:`PRIMITIVE_TAPS` for ``n = register_length``:
    the textbook m-sequence of period ``2^n - 1`` with ``2^(n-1)`` ones.  ``a_k`` is computed directly
    from ``(seed, k)`` as ``x^k mod p(x)`` applied to the initial bits (``O(n log k)``), so it does not
    depend on the order or frequency of evaluation.

    Parameters
    ----------
    amplitude, offset : float
        Levels ``offset +- amplitude``.
    bit_period : float
        Duration of one bit (s), > 0.
    seed : int
        Initial register, ``1 <= seed < 2^register_length``.
    register_length : int
        ``n``, 2 to 32: the period is ``2^n - 1`` bits.
    """

    not_state = ("amplitude", "bit_period", "seed", "register_length", "offset", "_polynomial")

    def __init__(self, amplitude: float = 1.0, bit_period: float = 1.0, seed: int = 1, register_length: int = 7,
                 offset: float = 0.0):
        super().__init__()
        self.amplitude, self.offset = scalar_parameter("amplitude", amplitude), scalar_parameter("offset", offset)
        self.bit_period = require_positive("bit_period", bit_period)
        n = self.register_length = integer_parameter("register_length", register_length, 2, 32,
                                                     "an integer from 2 to 32")
        self.seed = integer_parameter("seed", seed, 1, 2 ** n - 1, f"an integer from 1 to 2^{n} - 1 = {2 ** n - 1}")
        # bit j of the polynomial = coefficient of x^j, the leading x^n included
        self._polynomial = (1 << n) | sum(1 << (n - tap) for tap in PRIMITIVE_TAPS[n])

    def _times_x(self, r: int) -> int:
        r <<= 1
        return r ^ self._polynomial if r >> self.register_length & 1 else r

    def _multiply(self, a: int, b: int) -> int:
        """``a(x) b(x) mod p(x)`` over GF(2)."""
        product = 0
        while b:
            if b & 1:
                product ^= a
            b >>= 1
            a = self._times_x(a)
        return product

    def bit(self, k: int) -> int:
        """``a_k`` (0 or 1): ``x^k mod p = sum_j r_j x^j`` gives ``a_k = XOR_j r_j a_j``."""
        result, power = 1, 2           # x^0, x^1
        while k:
            if k & 1:
                result = self._multiply(result, power)
            power = self._multiply(power, power)
            k >>= 1
        return bin(result & self.seed).count("1") & 1

    def value(self, t):
        k = interval_index(t, self.bit_period)
        bits = np.vectorize(self.bit, otypes=[float])(k) if k.ndim else float(self.bit(int(k)))
        return self.offset + self.amplitude * (2.0 * np.asarray(bits) - 1.0)

    def parameters(self) -> np.ndarray:
        """``amplitude``, ``bit_period``, ``seed``, ``n``, the polynomial's bits, ``offset`` (:meth:`c_value`)."""
        return np.array([self.amplitude, self.bit_period, self.seed, self.register_length, self._polynomial,
                         self.offset], dtype=float)

    def c_value(self) -> str:
        """:meth:`value` in C: :func:`interval_index`, then :meth:`bit` by the same square-and-multiply over GF(2)."""
        return _C_VALUE
