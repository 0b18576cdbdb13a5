"""Issue 36: GPEBO on a larger plant, no noise -- the gamma estimate stays at round-off once right, and the
converged flag stays 1.

n = 4, a 3-dimensional beta generator whose whole gamma is unknown and a constant theta (p = 47 unknowns in the
gamma regression, k_gamma = 1e-30): on exact data |Delta| ranges from 1e-5 down to 3e-14, and Statement 2 with
a tiny k solves Y_i = Delta sigma_i outright at every sample -- also where Delta is near round-off, so an estimate
right to 4e-15 jumped to 8.8e-12.  The gamma DREM's round-off floor (RELATIVE_FLOOR) keeps such samples from
moving it: measured 1.1e-13 at worst after the first converged sample, the flag never dropping."""

from __future__ import annotations

import numpy as np

from obsfmu.fmus.system.inmemory import block_of
from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.block import Segment

FILE = """
name = "n4"
connections = ["source.y -> plant.u", "source.y -> observer.u", "plant.y -> observer.y"]
[experiment]
stop_time = 150.0
step = 1.0
master = "jacobi"
[components.source]
kind = "waveform"
amplitude = [1.0, 0.5]
omega = [1.0, 2.3]
[components.plant]
kind = "generator-plant"
Ts = 1.0
f = [0, "tanh(y)", 0, 0]
h_beta = [1, 0, 0]
H_theta = [[0], [1], [0], [0]]
gamma_beta = [0, 0, -1]
gamma_theta = [1]
xi_beta0 = [1.0, 0.5, -0.3]
xi_theta0 = [0.5]
x0 = [0.3, -0.2, 0.1, 0.05]
[components.observer]
kind = "gpebo-observer"
plant = "plant"
input = "source"
excitation_samples = 150
Ts = 1.0
gamma_beta_unknown = "all"
gamma_hat0 = [0.5, 0.5, 0.5, 0.5]
k_gamma = 1e-30
converged_tolerance = 1e-6
"""
GAMMA = np.array([0.0, 0.0, -1.0, 1.0])      # [gamma_beta (whole), g_theta]


def test_a_full_gamma_estimate_stays_at_round_off_and_the_flag_stays_up():
    definitions = {d.model_name.split("_")[-1]: d for d in parse_system(FILE, "n4.toml").definitions()}
    source, plant, observer = (block_of(definitions[name]) for name in ("source", "plant", "observer"))
    errors, flags = [], []
    for k in range(150):
        u, y = source.outputs(k, {})["y"], plant.outputs(k, {})["y"]
        observer.advance(k, 1.0, {"u": Segment.hold(u), "y": Segment.hold(y)})
        plant.advance(k, 1.0, {"u": Segment.hold(u)})
        out = observer.outputs(k + 1, {})
        errors.append(float(np.max(np.abs(out["gamma_hat"] - GAMMA))))
        flags.append(out["converged"][0])
    first = int(np.argmax(np.array(flags) == 1))
    assert flags[first] == 1 and first < 60                          # measured sample 46
    assert max(errors[first:]) < 1e-12                                # measured 1.1e-13 (8.8e-12 without the floor)
    assert all(flag == 1 for flag in flags[first:])
