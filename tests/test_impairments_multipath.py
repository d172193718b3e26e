"""Multipath in the generated IF (issue 15 item 3): the scalar receiver's DLL bias with one
replica against the early-late envelope for its spacing.

The receiver's DLL has early-to-prompt spacing 0.5 chip, so early-to-late d = 1 chip. For an
ideal (unfiltered) correlation triangle and a replica of amplitude alpha, delay delta, in
phase (+) or in anti-phase (-) with the direct signal, the tracking point is biased by
+-alpha delta / (1 +- alpha) for delta < d/2; the range d/2 .. 1 - d/2 is empty for d = 1;
between 1 - d/2 and 1 + d/2 it falls linearly, +-alpha (1 + d/2 - delta) / (2 -+ alpha);
from 1 + d/2 on it is zero (Braasch 1996; van Nee 1993).

Each case is generated with the same seed as a file without the replica, so the thermal
noise is the same sample for sample: the difference of the tracked code phases is the bias.
"""

import json

import numpy as np
import pytest

from sdr_di.receiver.run_scalar import open_source
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
from sdr_di.scenario.schema import parse_scenario
from sdr_di.sim.generate import generate_files

PRN = 27
FS = 5e6
DURATION = 1.6


def _file(tmp, name, multipath):
    sc0 = load_scenario(DEFAULT_SCENARIO)
    raw = json.loads(json.dumps(sc0.raw))
    raw["scenario"]["duration_s"] = DURATION
    raw["satellites"].update(prns=[PRN], cn0_dbhz=52.0)
    raw["signal"].update(sampling_rate_hz=FS, sample_format="iq_int16", quantization_bits=16)
    if multipath:
        raw["multipath"] = [multipath]
    sc = parse_scenario(raw, base_dir=sc0.source.parent)
    paths = generate_files(sc, tmp / name, progress=False)
    return paths["if"]


def _code_phases(path):
    """Tracked code phase [chips] of PRN at each output epoch after 0.8 s."""
    phases = {}

    def on_epoch(sample, obs, _eph):
        for o in obs:
            if o.prn == PRN and sample / FS > 0.8 and o.state == "TRACK":
                phases[sample] = o.code_phase_chips

    ScalarReceiver(log=False).run(open_source(path), prns=[PRN], on_epoch=on_epoch)
    return phases


def _bias_chips(direct, multi):
    """Mean delay bias [chips]: a later (delayed) tracking point has a smaller code phase."""
    common = sorted(set(direct) & set(multi))
    assert len(common) >= 5
    d = np.array([direct[s] - multi[s] for s in common])
    d = (d + 5115.0) % 10230.0 - 5115.0
    return float(np.mean(d))


def envelope(alpha, delta, sign, d=1.0):
    if delta < d / 2:
        return sign * alpha * delta / (1 + sign * alpha)
    if delta < 1 + d / 2:
        return sign * alpha * (1 + d / 2 - delta) / (2 - sign * alpha)
    return 0.0


@pytest.fixture(scope="module")
def direct(tmp_path_factory):
    return _code_phases(_file(tmp_path_factory.mktemp("mp"), "direct", None))


@pytest.mark.parametrize("delta,phase_deg", [(0.25, 0.0), (0.25, 180.0), (1.0, 0.0),
                                             (2.0, 180.0)])
def test_dll_bias_follows_the_early_late_envelope(tmp_path, direct, delta, phase_deg):
    alpha = 0.5
    path = _file(tmp_path, "mp", {"prn": PRN, "alpha": alpha, "delay_chips": delta,
                                  "phase_deg": phase_deg})
    bias = _bias_chips(direct, _code_phases(path))
    want = envelope(alpha, delta, 1.0 if phase_deg == 0.0 else -1.0)
    assert abs(bias - want) < 0.01 + 0.1 * abs(want), (bias, want)


def test_envelope_reference_values():
    """The formula the test checks against, at the issue's points (d = 1 chip)."""
    assert envelope(0.5, 0.25, 1) == pytest.approx(0.125 / 1.5)
    assert envelope(0.5, 0.25, -1) == pytest.approx(-0.25)
    assert envelope(0.5, 1.5, 1) == 0.0 and envelope(0.5, 3.0, -1) == 0.0
    # continuous at the edge of the linear range (delta -> 1.5)
    assert envelope(0.5, 1.4999, 1) == pytest.approx(0.0, abs=1e-4)


def test_ground_reflector_gives_the_image_antenna_delay_and_phase():
    """reflector = "ground": the replica's code lags the direct one by 2 h sin(el) / c and
    its carrier by that delay plus the reflection's half cycle."""
    from sdr_di.constants import C_LIGHT, CHIP_RATE_B3I, F_B3I
    from sdr_di.sim.generate import make_generator

    h = 12.0
    sc0 = load_scenario(DEFAULT_SCENARIO)
    raw = json.loads(json.dumps(sc0.raw))
    raw["scenario"]["duration_s"] = 0.05
    raw["satellites"].update(prns=[PRN])
    raw["multipath"] = [{"prn": PRN, "alpha": 0.3, "reflector": "ground",
                         "antenna_height_m": h}]
    gen = make_generator(parse_scenario(raw, base_dir=sc0.source.parent))
    st = gen.node_state(0, 3)
    el = np.radians(gen.sats[0].elevation_deg)
    tau = 2 * h * np.sin(el) / C_LIGHT
    lag = (st["chip0"][0, 0] - st["chip0"][1, 0]) % 10230.0
    assert lag == pytest.approx(tau * CHIP_RATE_B3I, abs=1e-4)
    assert 0.3 < lag < 0.9  # 24 m sin(el): a fraction of a chip
    dphase = (st["ph0"][1, 0] - st["ph0"][0, 0] - (0.5 - F_B3I * tau)) % 1.0
    assert min(dphase, 1 - dphase) < 2e-3
    assert st["amp"][1, 0] == pytest.approx(0.3 * st["amp"][0, 0])


@pytest.mark.parametrize("table,pattern", [
    ({"reflector": "ground"}, r"antenna_height_m"),
    ({"reflector": "ground", "antenna_height_m": 5.0, "delay_chips": 0.1},
     r"\.delay_chips: not with reflector"),
    ({"reflector": "wall", "antenna_height_m": 5.0}, r"\.reflector: 'wall' is not one of"),
    ({"reflector": "ground", "antenna_height_m": -1.0}, r"antenna_height_m: must be > 0"),
])
def test_bad_reflector_tables(table, pattern):
    import re

    from sdr_di.errors import ScenarioError

    sc0 = load_scenario(DEFAULT_SCENARIO)
    raw = json.loads(json.dumps(sc0.raw))
    raw["multipath"] = [{"prn": PRN, "alpha": 0.3, **table}]
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(raw, base_dir=sc0.source.parent)
    assert re.search(r"\[\[multipath\]\]\[0\]", str(exc.value)) and re.search(pattern,
                                                                            str(exc.value))
