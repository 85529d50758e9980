"""Tracking faults and smoothing filters: exact shifts, seeded noise, One Euro properties."""

import numpy as np
import pytest

from handsim.envs.teleop import (
    ExponentialFilter,
    FaultConfig,
    FaultInjector,
    InvalidFaults,
    InvalidFilter,
    OneEuroFilter,
    make_filter,
)
from handsim.envs.teleop.faults import sight_blocked
from handsim.envs.teleop.metrics import hand_penetration_m, high_frequency_rms_mm, lag_frames


def _ramp(n=30):
    return [np.full((21, 3), float(i)) for i in range(n)]


def _run(config, frames, seed=0):
    injector = FaultInjector(config, seed)
    return [injector(f) for f in frames]


def test_no_faults_pass_frames_unchanged():
    """No faults pass frames unchanged."""
    frames = _ramp()
    for (out, dropped), x in zip(_run(FaultConfig(), frames), frames, strict=True):
        assert not dropped
        np.testing.assert_array_equal(out, x)


@pytest.mark.parametrize("k", [1, 3, 7])
def test_latency_shifts_by_exactly_k_frames(k):
    """Latency shifts by exactly k frames."""
    frames = _ramp()
    out = [o for o, _ in _run(FaultConfig(latency_frames=k), frames)]
    for i in range(len(frames)):
        np.testing.assert_array_equal(out[i], frames[max(i - k, 0)])


def test_jitter_delays_within_bounds_and_never_goes_back_in_time():
    """Jitter delays within bounds and never goes back in time."""
    frames = _ramp(200)
    out = [o[0, 0] for o, _ in _run(FaultConfig(latency_frames=2, jitter_frames=3), frames)]
    delays = np.arange(200) - np.array(out)
    assert np.all(np.diff(out) >= 0)
    assert delays[10:].min() >= 2 and delays.max() <= 5
    assert len(set(delays[10:].tolist())) > 1


def test_noise_has_the_configured_std_and_is_seeded():
    """Noise has the configured std and is seeded."""
    frames = [np.zeros((21, 3))] * 400
    out = np.array([o for o, _ in _run(FaultConfig(noise_mm=10.0), frames)])
    assert out.std() * 1e3 == pytest.approx(10.0, rel=0.05)
    again = np.array([o for o, _ in _run(FaultConfig(noise_mm=10.0), frames)])
    np.testing.assert_array_equal(out, again)


def test_bias_is_a_constant_offset():
    """Bias is a constant offset."""
    out = _run(FaultConfig(bias_mm=(1.0, -2.0, 3.0)), [np.zeros((21, 3))])[0][0]
    np.testing.assert_allclose(out, np.tile([0.001, -0.002, 0.003], (21, 1)))


def test_dropout_holds_or_extrapolates():
    """Dropout holds or extrapolates."""
    frames = _ramp(300)
    held = _run(FaultConfig(dropout=0.3), frames)
    fraction = np.mean([d for _, d in held])
    assert 0.2 < fraction < 0.4
    for i, (out, dropped) in enumerate(held):
        if dropped and i > 0:
            np.testing.assert_array_equal(out, held[i - 1][0])
    extra = _run(FaultConfig(dropout=0.3, dropout_mode="extrapolate"), frames)
    # A ramp is extrapolated exactly (constant velocity) after two delivered frames.
    exact = [np.allclose(o, frames[i]) for i, (o, d) in enumerate(extra) if d and i > 2]
    assert exact and np.mean(exact) > 0.8


def test_occlusion_hides_points_behind_the_occluder():
    """Occlusion hides points behind the occluder."""
    points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    eye = np.array([0.0, 0.0, 1.0])
    blocked = sight_blocked(points, eye, np.array([0.0, 0.0, 0.5]), 0.02)
    assert blocked.tolist() == [True, False]
    rng = np.random.default_rng(0)
    hand = rng.normal(0.0, 0.03, (21, 3))
    out = _run(
        FaultConfig(occlusion_rate=1.0, occluder_radius_m=0.03, viewpoint_m=(0, 0, 1)), [hand] * 5
    )
    hidden = [np.isnan(o).all(axis=1).sum() for o, d in out if not d]
    assert hidden and all(h >= 1 for h in hidden)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"noise_mm": -1}, r"noise_mm must be a finite number \[0.0, 1000.0\]"),
        ({"dropout": 1.5}, r"dropout must be a finite number \[0.0, 1.0\]"),
        ({"dropout_mode": "zero"}, "dropout_mode='zero' is not valid; choose one of hold"),
        ({"latency_frames": 1.5}, r"latency_frames must be an int in \[0, 10000\]"),
        ({"bias_mm": (1, 2)}, r"bias_mm must be 3 finite numbers"),
        ({"occlusion_frames": 0}, "occlusion_frames must be >= 1"),
    ],
)
def test_bad_fault_settings(kwargs, message):
    """Bad fault settings."""
    with pytest.raises(InvalidFaults, match=message):
        FaultConfig(**kwargs)


# Filters ---------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [lambda: OneEuroFilter(90.0), lambda: ExponentialFilter(0.3)])
def test_constant_input_passes_unchanged(make):
    """Constant input passes unchanged."""
    f = make()
    x = np.random.default_rng(1).normal(size=(21, 3))
    for _ in range(50):
        np.testing.assert_array_equal(f(x), x)


def test_one_euro_smooths_noise_and_follows_a_step():
    """One euro smooths noise and follows a step."""
    rng = np.random.default_rng(0)
    f = OneEuroFilter(90.0, min_cutoff_hz=1.0, beta=0.0)
    noisy = rng.normal(0.0, 0.01, size=(500, 3))
    out = np.array([f(x) for x in noisy])
    assert out[100:].std() < 0.3 * noisy.std()
    # A larger beta follows a fast move with less lag.
    step = np.r_[np.zeros(20), np.linspace(0, 0.2, 20), np.full(40, 0.2)][:, None]
    lags = []
    for beta in (0.0, 50.0):
        g = OneEuroFilter(90.0, min_cutoff_hz=1.0, beta=beta)
        y = np.array([g(x) for x in step])
        lags.append(np.abs(y - step).sum())
    assert lags[1] < 0.5 * lags[0]


def test_one_euro_matches_the_reference_equations():
    """One euro matches the reference equations."""
    rate, fc, beta, dc = 60.0, 1.5, 2.0, 1.0
    f = OneEuroFilter(rate, min_cutoff_hz=fc, beta=beta, d_cutoff_hz=dc)
    xs = [0.0, 0.1, 0.15, 0.3]
    ys = [float(f(np.array(x))) for x in xs]

    def alpha(c):
        return 1.0 / (1.0 + 1.0 / (2 * np.pi * c) * rate)

    x_hat, dx_hat, prev = xs[0], 0.0, xs[0]
    expected = [xs[0]]
    for x in xs[1:]:
        dx = (x - prev) * rate
        dx_hat = dx_hat + alpha(dc) * (dx - dx_hat)
        x_hat = x_hat + alpha(fc + beta * abs(dx_hat)) * (x - x_hat)
        expected.append(x_hat)
        prev = x
    np.testing.assert_allclose(ys, expected, rtol=1e-12)


def test_filters_hold_untracked_coordinates():
    """Filters hold untracked coordinates."""
    f = OneEuroFilter(50.0)
    f(np.array([1.0, 2.0]))
    out = f(np.array([np.nan, 2.0]))
    assert np.isnan(out[0]) and out[1] == 2.0
    np.testing.assert_array_equal(f(np.array([1.0, 2.0])), [1.0, 2.0])


@pytest.mark.parametrize(
    ("name", "params", "message"),
    [
        ("kalman", {}, "filter='kalman' is not valid; choose one of none, one_euro, ema"),
        ("one_euro", {"min_cutoff_hz": 0}, "min_cutoff_hz must be a finite number > 0"),
        ("one_euro", {"gain": 1}, "filter 'one_euro': .*gain"),
        ("ema", {"alpha": 2}, r"alpha must lie in \(0, 1\]"),
        ("none", {"alpha": 1}, "filter 'none' takes no parameters"),
    ],
)
def test_bad_filters(name, params, message):
    """Bad filters."""
    with pytest.raises(InvalidFilter, match=message):
        make_filter(name, 50.0, **params)


# Metrics ---------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [0, 2, 5])
def test_lag_of_a_shifted_signal_is_exact(k):
    """Lag of a shifted signal is exact."""
    t = np.arange(200) * 0.02
    ref = np.stack([np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 0.3 * t)], axis=1)
    follower = np.concatenate([np.repeat(ref[:1], k, axis=0), ref[: len(ref) - k]])
    assert lag_frames(ref, follower, 20) == k


def test_jitter_measures_high_frequencies_only():
    """Jitter measures high frequencies only."""
    t = np.arange(500) * 0.01
    slow = 0.05 * np.sin(2 * np.pi * 0.5 * t)[:, None]
    assert high_frequency_rms_mm(slow, 0.01) < 0.05
    fast = slow + 0.001 * np.sin(2 * np.pi * 20 * t)[:, None]
    assert high_frequency_rms_mm(fast, 0.01) == pytest.approx(1.0 / np.sqrt(2), rel=0.05)


def test_penetration_without_contacts_is_zero():
    """Penetration without contacts is zero."""

    class Data:
        ncon = 0

    assert hand_penetration_m(Data(), np.zeros(3, bool)) == (0.0, False)
