"""The independent truth model (tests/truth/truth_model.py) is right before anything is judged by
it: its linear steady state matches the analytic transfer function, RK4 converges at its default
step, and its backlash is Modelica's ElastoBacklash (dead zone, a damper that never pulls)."""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "truth"))
import truth_model as tm  # noqa: E402


def steady_amplitude(t, x, w, t0, cycles=4):
    sel = (t >= t0) & (t < t0 + cycles * 2 * math.pi / w - 1e-9)  # whole cycles: no end point twice
    c = np.cos(w * t[sel])
    s = np.sin(w * t[sel])
    a = 2 * np.mean(x[sel] * s)
    b = 2 * np.mean(x[sel] * c)
    return math.hypot(a, b), math.atan2(b, a)


def test_linear_steady_state_matches_the_transfer_function():
    k, c, j, amp, f = 20.0, 0.3, 0.018, 0.3, 1.0
    w = 2 * math.pi * f
    p = {"stiffness": k, "damping": c, "inertia": j}
    t, x = tm.simulate(p, 12.0, 1e-4, lambda t: (amp * math.sin(w * t), amp * w * math.cos(w * t)))
    h = complex(k, w * c) / complex(k - j * w * w, w * c)
    got, phase = steady_amplitude(t, x, w, 8.0)  # 4 whole cycles after the transient (τ = 2J/C ≈ 0.12 s)
    assert abs(got - amp * abs(h)) < 1e-6 * amp, (got, amp * abs(h))
    assert abs(phase - math.atan2(h.imag, h.real)) < 1e-5


def test_rk4_converges_at_the_default_step_for_a_stiff_transmission():
    p = {"stiffness": 680.0, "damping": 0.1, "inertia": 0.018, "backlash": 0.0}
    m = lambda t: (0.3 * math.sin(2 * math.pi * t), 0.3 * 2 * math.pi * math.cos(2 * math.pi * t))  # noqa: E731
    _, coarse = tm.simulate(dict(p), 2.0, 1e-4, m)
    _, fine = tm.simulate(dict(p), 2.0, 5e-5, m)
    assert np.max(np.abs(coarse - fine[::2])) < 1e-8


def test_backlash_is_a_dead_zone_whose_damper_never_pulls():
    p = {"stiffness": 30.0, "damping": 2.0, "inertia": 0.018, "backlash": 0.02}
    assert tm.link_torque(0.005, 5.0, 0.0, dict(p)) == 0.0  # inside the play: nothing, whatever the speed
    assert math.isclose(tm.link_torque(0.015, 0.0, 0.0, dict(p)), 30.0 * 0.005)  # beyond it: the spring on the excess
    assert tm.link_torque(0.0101, -10.0, 0.0, dict(p)) == 0.0  # separating fast: the damper does not pull
    assert math.isclose(tm.link_torque(-0.015, 0.0, 0.0, dict(p)), -30.0 * 0.005)
