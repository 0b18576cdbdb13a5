"""plants/sources: every waveform against its formula written here, derivatives against finite
differences, the PRBS against an independent shift register and GF(2) theory, tables and CSV files
on known data, and every bad parameter named."""

from __future__ import annotations

import math

import numpy as np
import pytest

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.state import capture
from obsfmu.plants.sources import (PRBS, PRIMITIVE_TAPS, Chirp, Constant, CsvColumn, MultiSine, Ramp, Sine, Square, Step,
                            Table, interval_index)

TIMES = np.linspace(-1.0, 7.0, 1601)


def _sources():
    return [Constant(2.5), Step(1.0, 2.0, -1.0), Ramp(1.0, 2.0, 0.5, 3.0), Ramp(0.5, -1.0),
            Sine(2.0, 1.5, 0.3, 1.0), MultiSine([1.0, 0.5, 0.25], [0.5, 2.0, 3.0], [0.0, 1.0, -2.0], 0.2),
            Chirp(1.5, 0.5, 3.0, 1.0, 4.0, "linear"), Chirp(1.0, 0.5, 3.0, 1.0, 4.0, "exponential", "stop", 0.4, 1.0),
            Square(2.0, 0.8, 0.25, 1.0), PRBS(1.0, 0.1, 5, 7), Table([0.0, 1.0, 3.0], [1.0, 3.0, -1.0]),
            Table([0.0, 1.0, 3.0], [1.0, 3.0, -1.0], "previous")]


# --- waveforms against their formulas -------------------------------------------------------------------

def _chirp_expected(t, A, f0, f1, t0, t1, sweep, after, phase, offset):
    T = t1 - t0
    out = []
    for time in t:
        if time < t0 or (time >= t1 and after == "stop"):
            out.append(offset)
            continue
        tau = min(time - t0, T)
        if sweep == "linear":
            phi = 2 * math.pi * (f0 * tau + (f1 - f0) * tau ** 2 / (2 * T))
        else:
            k = (f1 / f0) ** (1 / T)
            phi = 2 * math.pi * f0 * (k ** tau - 1) / math.log(k)
        phi += phase + 2 * math.pi * f1 * max(time - t1, 0.0)
        out.append(offset + A * math.sin(phi))
    return np.array(out)


EXPECTED = {
    0: lambda t: np.full_like(t, 2.5),
    1: lambda t: np.where(t >= 1.0, 1.0, -1.0),
    2: lambda t: 0.5 + 2.0 * np.minimum(np.maximum(t - 1.0, 0.0), 2.0),
    3: lambda t: -np.maximum(t - 0.5, 0.0),
    4: lambda t: 1.0 + 2.0 * np.sin(3.0 * np.pi * t + 0.3),
    5: lambda t: 0.2 + np.sin(np.pi * t) + 0.5 * np.sin(4 * np.pi * t + 1.0) + 0.25 * np.sin(6 * np.pi * t - 2.0),
    6: lambda t: _chirp_expected(t, 1.5, 0.5, 3.0, 1.0, 4.0, "linear", "hold", 0.0, 0.0),
    7: lambda t: _chirp_expected(t, 1.0, 0.5, 3.0, 1.0, 4.0, "exponential", "stop", 0.4, 1.0),
    8: lambda t: np.array([1.0 + (2.0 if (time % 0.8) < 0.2 else -2.0) for time in t]),
    10: lambda t: np.array([1.0 if s <= 0 else 1.0 + 2.0 * s if s <= 1 else 3.0 - 2.0 * (s - 1) if s <= 3 else -1.0
                            for s in t]),
    11: lambda t: np.array([1.0 if s < 1 else 3.0 if s < 3 else -1.0 for s in t]),
}


@pytest.mark.parametrize("index", sorted(EXPECTED))
def test_waveform_against_its_formula(index):
    source = _sources()[index]
    times = TIMES
    if isinstance(source, Square):      # keep away from the edges, where the formula's % rounds differently
        times = times[np.abs((times / 0.8 * 4 + 0.5) % 1 - 0.5) > 1e-6]
    expected = EXPECTED[index](times)
    np.testing.assert_allclose(source.value(times), expected, rtol=0, atol=1e-12)
    for t in times[::37]:               # the block's output is the same number, one element
        assert source.outputs(float(t), {})["y"].tolist() == [pytest.approx(float(source.value(t)), abs=0)]


def test_square_edges_fall_on_computed_times():
    """A switching time computed in floating point is on the new level (right-continuous)."""
    square = Square(1.0, 0.1, 0.3)
    for k in range(50):
        assert square.value(k * 0.1) == 1.0 and square.value(k * 0.1 + 0.1 * 0.3) == -1.0
        assert square.value(k * 0.1 - 1e-6) == -1.0 and square.value(k * 0.1 + 0.03 - 1e-6) == 1.0


def test_sources_are_stateless_blocks_with_one_output():
    for source in _sources():
        assert source.input_sizes == {} and source.output_sizes == {"y": 1}
        assert source.stateless and not source.feedthrough
        assert capture(source) == {}, type(source).__name__
        before = source.outputs(2.0, {})["y"]
        source.advance(2.0, 0.1, {})
        assert source.outputs(2.0, {})["y"] == before


# --- derivatives ----------------------------------------------------------------------------------------

BREAKS = [0.0, 0.5, 1.0, 3.0, 4.0]     # step, ramp, chirp and table break points


@pytest.mark.parametrize("index", range(len(_sources())))
def test_derivative_against_central_difference(index):
    source = _sources()[index]
    h = 1e-6
    times = TIMES[np.min(np.abs(TIMES[:, None] - np.array(BREAKS)[None, :]), axis=1) > 1e-3]
    if isinstance(source, (Square, PRBS)):    # piecewise constant: the edges are where the value jumps
        times = times[np.abs(source.value(times + h) - source.value(times - h)) == 0]
    difference = (source.value(times + h) - source.value(times - h)) / (2 * h)
    scale = max(1.0, float(np.max(np.abs(difference))))
    np.testing.assert_allclose(source.derivative(times), difference, rtol=0, atol=1e-6 * scale)
    assert np.shape(source.derivative(times)) == times.shape


def test_derivative_at_a_break_is_the_one_from_the_right():
    h = 1e-8
    cases = [(Ramp(1.0, 2.0, 0.5, 3.0), [1.0, 3.0]), (Table([0.0, 1.0, 3.0], [1.0, 3.0, -1.0]), [0.0, 1.0, 3.0]),
             (Chirp(1.5, 0.5, 3.0, 1.0, 4.0), [1.0, 4.0]),
             (Chirp(1.0, 0.5, 3.0, 1.0, 4.0, after="stop", phase=1.0), [1.0, 4.0])]
    for source, breaks in cases:
        for t in breaks:
            right = (source.value(t + h) - source.value(t)) / h
            assert source.derivative(t) == pytest.approx(right, abs=1e-5), (type(source).__name__, t)
    assert Ramp(1.0, 2.0).derivative(1.0) == 2.0 and Ramp(1.0, 2.0, end_time=3.0).derivative(3.0) == 0.0


# --- PRBS -----------------------------------------------------------------------------------------------

def _fibonacci(n: int, seed: int, count: int) -> list[int]:
    """The textbook shift register, written out: a[k + n] = XOR of a[k + n - tap]."""
    bits = [(seed >> j) & 1 for j in range(n)]
    while len(bits) < count:
        new = 0
        for tap in PRIMITIVE_TAPS[n]:
            new ^= bits[len(bits) - tap]
        bits.append(new)
    return bits[:count]


@pytest.mark.parametrize("n", sorted(PRIMITIVE_TAPS))
def test_prbs_is_the_shift_register_sequence(n):
    for seed in (1, 2 ** n - 1, (0x5A5A5A5A % (2 ** n - 1)) + 1):
        prbs = PRBS(seed=seed, register_length=n)
        assert [prbs.bit(k) for k in range(300)] == _fibonacci(n, seed, 300)


def _poly_mod(a: int, p: int) -> int:
    degree = p.bit_length() - 1
    while a.bit_length() - 1 >= degree:
        a ^= p << (a.bit_length() - 1 - degree)
    return a


def _x_power(e: int, p: int) -> int:
    result, base = 1, 2
    while e:
        if e & 1:
            result = _poly_mod(_clmul(result, base), p)
        base = _poly_mod(_clmul(base, base), p)
        e >>= 1
    return result


def _clmul(a: int, b: int) -> int:
    out = 0
    while b:
        if b & 1:
            out ^= a
        a <<= 1
        b >>= 1
    return out


def _prime_factors(m: int) -> set[int]:
    found, d = set(), 2
    while d * d <= m:
        while m % d == 0:
            found.add(d)
            m //= d
        d += 1
    return found | ({m} if m > 1 else set())


@pytest.mark.parametrize("n", sorted(PRIMITIVE_TAPS))
def test_prbs_polynomial_is_primitive_so_the_period_is_maximal(n):
    """x has order exactly 2^n - 1 modulo the characteristic polynomial: the period is 2^n - 1."""
    p = (1 << n) | sum(1 << (n - tap) for tap in PRIMITIVE_TAPS[n])
    period = 2 ** n - 1
    assert _x_power(period, p) == 1
    assert all(_x_power(period // q, p) != 1 for q in _prime_factors(period))
    prbs = PRBS(seed=3 % period or 1, register_length=n)
    for k in (0, 17, 10 ** 6, 2 ** 40 + 5):
        assert prbs.bit(k) == prbs.bit(k + period)


@pytest.mark.parametrize("n", range(2, 12))
def test_prbs_period_and_balance_counted(n):
    period = 2 ** n - 1
    bits = [PRBS(seed=1, register_length=n).bit(k) for k in range(2 * period)]
    assert bits[:period] == bits[period:]
    assert min(p for p in range(1, period + 1) if bits[p:p + period] == bits[:period]) == period
    assert sum(bits[:period]) == 2 ** (n - 1)            # one more 1 than 0 in a period
    assert _runs(bits[:period]) == _m_sequence_runs(n)
    values = PRBS(2.0, 0.5, 1, n, offset=1.0).value(np.arange(period) * 0.5 + 0.25)
    assert sorted(set(values.tolist())) == [-1.0, 3.0] and values.mean() == pytest.approx(1.0 + 2.0 / period)


def _runs(bits: list[int]) -> dict[tuple[int, int], int]:
    """(bit, length) -> count of the maximal runs of the cyclic sequence ``bits`` (it has both bits)."""
    start = next(i for i in range(len(bits)) if bits[i] != bits[i - 1])
    rotated, counts, length = bits[start:] + bits[:start], {}, 1
    for previous, bit in zip(rotated, rotated[1:] + rotated[:1]):
        if bit == previous:
            length += 1
        else:
            counts[(previous, length)] = counts.get((previous, length), 0) + 1
            length = 1
    return counts


def _m_sequence_runs(n: int) -> dict[tuple[int, int], int]:
    """Golomb's run property of an m-sequence: 2^(n-k-2) runs of length k of each bit for k <= n - 2,
    one run of n - 1 zeros, one run of n ones."""
    counts = {(bit, k): 2 ** (n - k - 2) for bit in (0, 1) for k in range(1, n - 1)}
    return counts | {(0, n - 1): 1, (1, n): 1}


def test_prbs_value_depends_only_on_seed_and_bit_index():
    a, b = PRBS(1.0, 0.1, 9, 10), PRBS(1.0, 0.1, 9, 10)
    times = np.random.default_rng(0).uniform(0.0, 50.0, 400)
    scalar = [float(a.value(t)) for t in times]
    assert scalar == b.value(times[::-1])[::-1].tolist()
    assert scalar == [2.0 * a.bit(int(np.floor(t / 0.1 + 1e-9))) - 1.0 for t in times]
    slower = PRBS(1.0, 0.3, 9, 10)
    assert [slower.value(k * 0.3 + 0.1) for k in range(100)] == [a.value(k * 0.1 + 0.05) for k in range(100)]
    assert [PRBS(seed=9, register_length=10).bit(k) for k in range(64)] != [PRBS(seed=10, register_length=10).bit(k)
                                                                          for k in range(64)]
    assert [PRBS(seed=9.0, register_length=10.0).bit(k) for k in range(64)] == [a.bit(k) for k in range(64)]
    assert interval_index(-0.5, 0.1) == 0 and interval_index(0.3, 0.1) == 3


# --- tables and CSV -------------------------------------------------------------------------------------

def test_table_interpolation_on_known_data():
    table = Table([0.0, 2.0, 3.0], [1.0, 5.0, 2.0])
    assert table.value(np.array([-1.0, 0.0, 0.5, 2.0, 2.5, 3.0, 9.0])).tolist() == [1.0, 1.0, 2.0, 5.0, 3.5, 2.0, 2.0]
    assert table.derivative(np.array([-1.0, 0.0, 1.9, 2.0, 2.9, 3.0, 9.0])).tolist() == [0, 2, 2, -3, -3, 0, 0]
    previous = Table([0.0, 2.0, 3.0], [1.0, 5.0, 2.0], "previous")
    assert previous.value(np.array([-1.0, 0.0, 1.99, 2.0, 2.5, 3.0, 9.0])).tolist() == [1, 1, 1, 5, 5, 2, 2]
    assert Table([1.0], [4.0]).value(np.array([0.0, 1.0, 2.0])).tolist() == [4.0, 4.0, 4.0]


def _write(tmp_path, text, name="data.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_csv_column_with_interpolation(tmp_path):
    path = _write(tmp_path, "time, u ,y\n0,1,10\n1,3,20\n\n3,-1,30\n")
    column = CsvColumn(path, "y")
    assert column.value(np.array([-1.0, 0.5, 2.0, 4.0])).tolist() == [10.0, 15.0, 25.0, 30.0]
    assert column.derivative(2.0) == 5.0
    previous = CsvColumn(path, "u", interpolation="previous")
    assert previous.value(np.array([0.5, 1.0, 2.9, 3.5])).tolist() == [1, 3, 3, -1]
    assert CsvColumn(path, "time", time_column="y").value(15.0) == 0.5
    assert capture(column) == {}
    with_bom = _write(tmp_path, "\ufefftime,y\n0,1\n2,5\n", "excel.csv")
    assert CsvColumn(with_bom, "y").value(1.0) == 3.0


@pytest.mark.parametrize("text, column, message", [
    ("time,y\n0,1\n1,x\n", "y", r"data.csv: row 3, column 'y': expected a number, got 'x'"),
    ("time,y\n0,1\n1,nan\n", "y", r"data.csv: row 3, column 'y': 'nan' is not finite"),
    ("time,y\n0,1\n1\n", "y", r"data.csv: row 3, column 'y': missing"),
    ("time,y\n0,1\n2,1\n2,3\n", "y", r"data.csv: row 4: time 2 is not after 2 of row 3"),
    ("time,y\n0,1\n", "v", r"column: 'v' is not a column of .*data.csv \(columns: time, y\)"),
    ("t,y\n0,1\n", "y", r"time_column: 'time' is not a column"),
    ("", "y", r"path: .*data.csv is empty"),
    ("time,y\n", "y", r"path: .*data.csv has a header but no data rows"),
])
def test_csv_bad_data_is_named(tmp_path, text, column, message):
    with pytest.raises(ParameterError, match=message):
        CsvColumn(_write(tmp_path, text), column)


def test_csv_missing_file_is_named(tmp_path):
    with pytest.raises(ParameterError, match=r"path: cannot read .*nothing.csv: No such file or directory$"):
        CsvColumn(tmp_path / "nothing.csv", "y")
    with pytest.raises(ParameterError, match=r"interpolation: expected 'linear' or 'previous'"):
        CsvColumn(_write(tmp_path, "time,y\n0,1\n"), "y", interpolation="cubic")


# --- bad parameters -------------------------------------------------------------------------------------

@pytest.mark.parametrize("build, message", [
    (lambda: Constant("a"), r"^value: expected numbers"),
    (lambda: Step(time=math.nan), r"^time: .*is not finite"),
    (lambda: Step(height=[1, 2]), r"^height: expected 1 entries"),
    (lambda: Ramp(2.0, 1.0, end_time=1.0), r"^end_time: must be after start_time = 2"),
    (lambda: Ramp(slope=math.inf), r"^slope: "),
    (lambda: Sine(frequency_hz=-1.0), r"^frequency_hz: must be >= 0"),
    (lambda: Sine(phase="x"), r"^phase: expected numbers"),
    (lambda: MultiSine([1, 2], [1]), r"^frequencies_hz: expected 2 entries"),
    (lambda: MultiSine([1, 2], [1, 2], [0]), r"^phases: expected 2 entries"),
    (lambda: MultiSine([1], [1], offset=[]), r"^offset: expected 1 entries"),
    (lambda: Chirp(t0=2.0, t1=2.0), r"^t1: must be after t0 = 2"),
    (lambda: Chirp(f0_hz=0.0, sweep="exponential"), r"^f0_hz: must be > 0"),
    (lambda: Chirp(f1_hz=-1.0), r"^f1_hz: must be >= 0"),
    (lambda: Chirp(sweep="log"), r"^sweep: expected 'linear' or 'exponential', got 'log'"),
    (lambda: Chirp(after="loop"), r"^after: expected 'hold' or 'stop', got 'loop'"),
    (lambda: Square(period=0.0), r"^period: must be > 0"),
    (lambda: Square(duty=1.0), r"^duty: must be in \(0, 1\), got 1"),
    (lambda: PRBS(bit_period=-1.0), r"^bit_period: must be > 0"),
    (lambda: PRBS(register_length=33), r"^register_length: expected an integer from 2 to 32, got 33"),
    (lambda: PRBS(register_length=7.5), r"^register_length: "),
    (lambda: PRBS(seed=0), r"^seed: expected an integer from 1 to 2\^7 - 1 = 127, got 0"),
    (lambda: PRBS(seed=128), r"^seed: .* got 128"),
    (lambda: PRBS(seed=1.5), r"^seed: "),
    (lambda: PRBS(seed=True), r"^seed: "),
    (lambda: Table([0, 1, 1], [1, 2, 3]), r"^times: must be strictly increasing, entry 3 \(1\) is not after entry 2"),
    (lambda: Table([0, 1], [1, 2, 3]), r"^values: expected 2 entries"),
    (lambda: Table([], []), r"^times: expected at least one entry"),
])
def test_bad_parameter_is_named(build, message):
    with pytest.raises(ParameterError, match=message):
        build()
