"""Channel state machine on a scheduled blockage: TRACK -> LOST -> REACQUIRE -> PULL_IN ->
TRACK, with the time (transmit time) carried through the outage.

A 5 s, 5 MHz file holds three D1 satellites and the D2 GEO C05; the scenario's ``[[outage]]``
schedule blocks the first D1 satellite and C05 completely from 2.0 s to 3.0 s, and the third
D1 satellite from the start to 1.2 s (not found by the initial acquisition: found by the
periodic retry). The schedule cannot be set through ``with_overrides``: the raw scenario
dictionary is edited.
"""

import json

import numpy as np
import pytest

from sdr_di.receiver.ifreader import IfSource
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.receiver.tracking import ChannelState
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario, parse_scenario
from sdr_di.sim.generate import generate_files, make_generator

FS = 5e6
L = 10230
C = 299792458.0
T_OFF, T_ON = 2.0, 3.0
T_LATE = 1.2


@pytest.fixture(scope="module")
def outage_run(tmp_path_factory):
    sc0 = load_scenario(DEFAULT_SCENARIO)
    d1 = [s.prn for s in make_generator(sc0.with_overrides(duration_s=1.0)).sats if s.is_d1][:3]
    raw = json.loads(json.dumps(sc0.raw))
    raw["scenario"]["duration_s"] = 5.0
    raw["signal"]["sampling_rate_hz"] = FS
    raw["satellites"]["prns"] = d1 + [5]
    raw["outage"] = [{"prn": d1[0], "start_s": T_OFF, "end_s": T_ON, "blockage": True},
                     {"prn": "C05", "start_s": T_OFF, "end_s": T_ON, "blockage": True},
                     {"prn": d1[2], "start_s": 0.0, "end_s": T_LATE, "blockage": True}]
    sc = parse_scenario(raw, source=sc0.source, base_dir=sc0.source.parent)
    assert len(sc.outages) == 3
    out = tmp_path_factory.mktemp("outage")
    meta = generate_files(sc, out, name="outage", progress=False)["metadata"]
    gen = make_generator(sc)
    epochs = []
    rx = ScalarReceiver(retry_acquisition_s=0.5)
    logs = rx.run(IfSource.from_sidecar(meta), prns=[s.prn for s in gen.sats],
                  on_epoch=lambda s, obs, eph: epochs.append((s, obs)), epoch_interval_s=0.1)
    return sc, gen, rx, logs, epochs, d1


def _states(ch, fs):
    return [(s / fs, st) for s, st in ch.transitions]


def test_blocked_satellites_go_lost_and_reacquire(outage_run):
    _sc, _gen, rx, logs, _epochs, d1 = outage_run
    for prn in (d1[0], 5):
        ch = rx.channels[prn]
        tr = _states(ch, FS)
        names = [st for _, st in tr]
        # acquired, tracked, lost in the outage, re-acquired after it, tracked again
        assert names[:2] == [ChannelState.PULL_IN, ChannelState.TRACK], tr
        i_lost = names.index(ChannelState.LOST)
        t_lost = tr[i_lost][0]
        assert T_OFF < t_lost < T_OFF + 0.6, tr
        assert ChannelState.REACQUIRE in names[i_lost:], tr
        i_pull = names.index(ChannelState.PULL_IN, i_lost)
        assert T_ON <= tr[i_pull][0] < T_ON + 0.6, tr  # narrow search every 0.5 s
        assert names[-1] == ChannelState.TRACK and tr[-1][0] < T_ON + 1.2, tr
        assert ch.n_acquisitions == 2 and ch.slip_count >= 1
        # no correlation (no log row) while lost
        lg = logs[prn]
        assert not np.any((lg.time_s > t_lost + 0.01) & (lg.time_s < tr[i_pull][0] - 0.01))
    # the unblocked satellite is not disturbed
    ch = rx.channels[d1[1]]
    assert [st for _, st in ch.transitions] == [ChannelState.PULL_IN, ChannelState.TRACK]
    assert ch.n_acquisitions == 1


def test_observations_through_the_outage(outage_run):
    _sc, gen, rx, _logs, epochs, d1 = outage_run
    n = gen.n_per_node
    prns = [s.prn for s in gen.sats]
    seen = {p: [] for p in prns}
    for s, obs in epochs:
        t = s / FS
        for o in obs:
            seen[o.prn].append(t)
            k = prns.index(o.prn)
            if o.state != "TRACK" or not o.code_lock:
                continue
            if o.prn in (d1[0], 5) and T_OFF <= t < T_OFF + 0.6:
                continue  # signal gone, loss not yet declared (lock-detector latency)
            j = s // n
            st = gen.node_state(j, 1)
            dcode = (o.code_phase_chips - st["chip0"][k, 0] + L / 2) % L - L / 2
            assert abs(dcode) < 0.05, (o.prn, t, dcode)
            if o.time_valid:
                sat = gen.sats[k]
                t_true = sat.nav.t0 + st["ms0"][k, 0] * 1e-3 + st["chip0"][k, 0] / 10.23e6
                assert abs(o.t_tx_sow - t_true) * C < 5.0, (o.prn, t)
    for prn in (d1[0], 5):
        gap = [t for t in seen[prn] if T_OFF + 0.6 < t < T_ON]
        assert not gap, f"C{prn:02d} reported while blocked"
        assert max(seen[prn]) > 4.8
    assert len(seen[d1[1]]) == len(epochs)
    assert min(seen[d1[2]]) > T_LATE
    # C05 had frame sync before the outage and has a valid time again after it
    last = next(o for o in epochs[-1][1] if o.prn == 5)
    assert last.time_valid and last.carrier_lock
    before = [o for s, obs in epochs for o in obs if o.prn == 5 and s / FS < T_OFF]
    assert before[-1].time_valid
    # the code-epoch count was carried through the outage: the time is valid again as soon
    # as the bit edges are found (a new subframe would take at least 0.6 s more)
    t_track = [s / FS for s, st in rx.channels[5].transitions if st == ChannelState.TRACK][-1]
    t_valid = min(s / FS for s, obs in epochs for o in obs
                  if o.prn == 5 and s / FS > T_ON and o.time_valid)
    assert t_valid < t_track + 0.5, (t_track, t_valid)


def test_satellite_absent_at_start_is_found_by_the_retry(outage_run):
    _sc, gen, rx, logs, _epochs, d1 = outage_run
    ch = rx.channels[d1[2]]
    assert not rx.acquisition_results[[s.prn for s in gen.sats].index(d1[2])].detected
    tr = _states(ch, FS)
    assert [st for _, st in tr] == [ChannelState.PULL_IN, ChannelState.TRACK], tr
    assert T_LATE <= tr[0][0] < T_LATE + 0.6, tr  # retries every 0.5 s
    assert ch.n_acquisitions == 1
    k = [s.prn for s in gen.sats].index(d1[2])
    lg = logs[d1[2]]
    n = gen.n_per_node
    j = np.arange(4000, 4990)
    st = gen.node_state(4000, 990)
    dcode = (lg.code_phase_at(j * n) - st["chip0"][k] + L / 2) % L - L / 2
    assert np.abs(dcode).max() < 0.05
