"""Frame conversions of sdr_di.frames: the in-place forms against their defining stacks."""

import numpy as np
import pytest

from sdr_di.frames import C_e_n, ecef_to_llh, elevation_azimuth, llh_to_ecef


@pytest.mark.parametrize("shape", [(), (5,), (4, 7)])
def test_c_e_n_rows_are_east_north_up(shape):
    """C_e_n (filled in place) equals the rows E, N, U of its definition, stacked, bit for
    bit, for scalars and arrays, and is a rotation."""
    rng = np.random.default_rng(3)
    lat, lon = rng.uniform(-1.5, 1.5, shape), rng.uniform(-3.2, 3.2, shape)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    ref = np.stack([np.stack([-so, co, np.zeros_like(sl)], axis=-1),
                    np.stack([-sl * co, -sl * so, cl], axis=-1),
                    np.stack([cl * co, cl * so, sl], axis=-1)], axis=-2)
    C = C_e_n(lat, lon)
    assert C.shape == shape + (3, 3) and C.tobytes() == ref.tobytes()
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape),
                               atol=1e-15)


@pytest.mark.parametrize("shape", [(), (6,)])
def test_llh_round_trip_and_given_llh(shape):
    """llh_to_ecef / ecef_to_llh keep their shapes and invert each other; elevation_azimuth
    with the receiver's llh given is the same as with it computed."""
    rng = np.random.default_rng(4)
    llh = np.stack([rng.uniform(-1.4, 1.4, shape), rng.uniform(-3, 3, shape),
                    rng.uniform(-50, 9000, shape)], axis=-1)
    r = llh_to_ecef(llh[..., 0], llh[..., 1], llh[..., 2])
    assert r.shape == shape + (3,)
    back = ecef_to_llh(r)
    assert back.shape == shape + (3,)
    np.testing.assert_allclose(back[..., :2], llh[..., :2], atol=1e-12)
    np.testing.assert_allclose(back[..., 2], llh[..., 2], atol=1e-6)
    sats = r[..., None, :] + rng.uniform(-2e7, 2e7, shape + (5, 3))
    r_rx = r[..., None, :]
    el0, az0 = elevation_azimuth(r_rx, sats)
    el1, az1 = elevation_azimuth(r_rx, sats, llh=ecef_to_llh(r_rx))
    assert el0.tobytes() == el1.tobytes() and az0.tobytes() == az1.tobytes()
