"""The measurement-noise estimate of a record, against records of known noise."""

from __future__ import annotations

import math

import numpy as np

from hdgym.discrepancy import noise as N
from hdgym.discrepancy import residuals as R
from hdgym.discrepancy import truth as T

DT = 1e-3
CUTOFF = R.default_cutoff(DT)


def _signal(n: int = 6000) -> np.ndarray:
    """A smooth signal with a few steps (a commanded current), arbitrary units."""
    t = np.arange(n) * DT
    steps = np.repeat(np.random.default_rng(3).uniform(-2.0, 2.0, 12), n // 12)
    return np.sin(2 * math.pi * 0.7 * t) + steps


def test_white_noise_is_read_through_steps_and_a_smooth_signal():
    rng = np.random.default_rng(0)
    s = _signal()
    for sigma in (0.003, 0.02, 0.1):
        e = rng.normal(0.0, sigma, s.size)
        assert abs(N.white_sigma(s + e) / sigma - 1.0) < 0.1, sigma
        # the old first-difference estimate reads the steps as noise
        old = math.sqrt(float(np.var(np.diff(s + e))) / 2.0)
        if sigma == 0.003:
            assert old > 3.0 * sigma
    # the filtered channel's noise: the estimate against the noise actually left after the filter
    e = rng.normal(0.0, 0.02, s.size)
    raw = R.Raw(np.zeros(s.size), motor_current=s + e)
    measured = R.channels(raw, ("motor_current",), 1.0, DT, CUTOFF)
    est = N.noise_nmse(raw, ("motor_current",), 1.0, DT, CUTOFF, measured)
    left = float(np.var(R.lowpass(e, DT, CUTOFF)))
    true = 100.0 * left / float(np.var(measured["motor_current"]))
    assert abs(est["motor_current"] / true - 1.0) < 0.25, (est, true)


def test_quantization_noise_of_speed_and_angle_from_a_quantized_angle():
    counts = 4000.0
    t = np.arange(6000) * DT
    for amp, hz in ((30.0, 1.0), (0.05, 0.5)):  # fast (many counts per sample), slow
        theta = amp * np.sin(2 * math.pi * hz * t) + 0.3 * np.sin(2 * math.pi * 7 * t) * amp / 30
        meas = R.quantize(theta, counts)
        for name, deriv in (("motor_speed", True), ("motor_angle", False)):
            raw = R.Raw(meas)
            ch = R.channels(raw, (name,), 1.0, DT, CUTOFF)[name]
            clean = R.channels(R.Raw(theta), (name,), 1.0, DT, CUTOFF)[name]
            true = 100.0 * float(np.var(ch - clean)) / float(np.var(ch))
            est = N.noise_nmse(raw, (name,), 1.0, DT, CUTOFF, {name: ch}, (counts, None))[name]
            assert 0.4 < est / true < 2.5, (amp, name, est, true)
            # the old estimate: var(diff)/2 of the raw channel times the kept share of the band
            x = np.gradient(meas, DT) if deriv else meas
            old = 100.0 * float(np.var(np.diff(x))) / 2.0 * 2 * CUTOFF * DT / float(np.var(ch))
            if deriv and amp > 1.0:  # the old estimate took the speed's quantization as white
                assert old > 10.0 * true


def test_a_simulated_record_and_its_true_sensor_noise():
    from hdgym.discrepancy.problem import Problem
    from hdgym.params import preset
    from hdgym.record import Record
    from hdgym.sim import Simulator

    p = preset("tuttle-joint3")
    rec = Simulator(p).run("sine:0.78:2", 3.0, seed=2)
    clean = Simulator(p, sensors=False).run("sine:0.78:2", 3.0, seed=2)
    prob = Problem(Record(dict(rec.columns), dict(rec.meta), "x"), p)
    true = T.true_noise_nmse(prob, clean)
    est = N.noise_nmse(prob.raw, prob.names, prob.ratio, prob.dt, prob.cutoff, prob.measured,
                       prob.counts)
    for k in prob.names:
        assert 0.3 < est[k] / true[k] < 3.0, (k, est[k], true[k])
    # the joint that made the record, compared in one run, is exact on the angle channels
    prob.segment = 0.0
    assert prob.nmse(p)["motor_speed"] < 1e-9


def test_gap_cut():
    assert T.gap_cut(10.0, 5.0, 4.5) == 5.0 / 5.5
    assert T.gap_cut(10.0, 4.0, 5.0) > 1.0  # below the truth: more than the gap
    assert math.isnan(T.gap_cut(1.0, 0.5, 2.0))  # the truth above before: no gap
    assert math.isnan(T.gap_cut(1.0, 0.5, math.nan))


def test_channel_selection_reads_the_sensor_noise_not_fast_content():
    """A current or torque channel is compared when its filtered signal stands SNR x (RMS)
    above its filtered sensor noise. Fast content the channel filter removes (a 100 Hz line)
    is no sensor noise: the old first-difference estimate read it as such and dropped
    channels 6-60 x above their noise; the third-difference estimate keeps them, and still
    drops a channel that is truly below the ratio."""
    t = np.arange(6000) * DT
    rng = np.random.default_rng(5)
    gain = N.white_gain(DT, CUTOFF)
    for slow, line, sigma, keep in ((0.05, 0.1, 0.002, True), (0.05, 0.1, 0.02, True),
                                    (0.002, 0.0, 0.002, False)):
        x = (slow * np.sin(2 * math.pi * t) + line * np.sin(2 * math.pi * 100.0 * t + 0.3)
             + rng.normal(0.0, sigma, t.size))
        signal = float(np.var(R.lowpass(x, DT, CUTOFF)))
        true_snr = math.sqrt(signal / (sigma**2 * gain))
        assert (true_snr > N.SNR) == keep, true_snr  # the case is what it claims to be
        assert N.snr_ok(x, DT, CUTOFF) == keep, (slow, line, sigma)
        old = float(np.var(np.diff(x))) / 2.0 * 2.0 * CUTOFF * DT
        if line:  # the old estimate dropped it
            assert signal < N.SNR**2 * old
        raw = R.Raw(np.zeros(t.size), output_torque=x, motor_current=x)
        names = N.pick_channels(raw, True, 100.0, DT, CUTOFF, 4000.0, None)
        assert ("output_torque" in names) == keep and ("motor_current" in names) == keep


def test_channel_selection_on_a_record_of_known_noise():
    """tuttle-joint3 turning at constant current: the torque stands ~240 x above its sensor
    noise (kept), the current ~2 x (dropped; both measured against the true noise)."""
    from hdgym.params import preset
    from hdgym.sim import Simulator

    p = preset("tuttle-joint3")
    rec = Simulator(p).run("step:0.30", 3.0, seed=1)
    raw = R.Raw(np.asarray(rec.motor_angle), np.asarray(rec.output_angle),
                np.asarray(rec.output_torque), np.asarray(rec.motor_current))
    names = N.pick_channels(raw, False, p.ratio, DT, CUTOFF, p.sensors.motor_counts,
                            p.sensors.output_counts)
    assert "output_torque" in names and "motor_current" not in names


def test_a_motor_that_never_moves_gives_no_motion_channel():
    """A current below breakaway never turns the motor encoder by a count: the speed channel
    has no variance and so no NMSE scale (a base model creeping by a count read 10^302 %,
    hold-out tuttle-joint3 / stribeck_friction / sine:0.157:2, seed 86). It is compared only
    when no other channel is left."""
    from hdgym.params import preset
    from hdgym.sim import Simulator

    p = preset("tuttle-joint3")
    still = Simulator(p).run("sine:0.157:2", 1.0, seed=1)
    assert np.ptp(still.motor_angle) == 0.0
    raw = R.Raw(np.asarray(still.motor_angle), np.asarray(still.output_angle),
                np.asarray(still.output_torque), np.asarray(still.motor_current))
    args = (p.ratio, DT, CUTOFF, p.sensors.motor_counts, p.sensors.output_counts)
    names = N.pick_channels(raw, False, *args)
    assert names and "motor_speed" not in names
    bare = R.Raw(np.asarray(still.motor_angle), np.asarray(still.output_angle))
    assert N.pick_channels(bare, False, *args) == ("motor_speed",)
    assert N.pick_channels(bare, True, *args) == ("motor_angle",)
    moving = Simulator(p).run("step:0.30", 1.0, seed=1)
    raw = R.Raw(np.asarray(moving.motor_angle), np.asarray(moving.output_angle))
    assert N.pick_channels(raw, False, *args)[0] == "motor_speed"


def test_ringing_above_the_band_is_not_read_as_noise():
    """A stick-slip torque rings at each slip far above the channel filter's band: the third
    differences read that ringing as noise, the spectrum's floor does not, and
    :func:`white_sigma` keeps the lower reading (white noise alone reads alike on both)."""
    rng = np.random.default_rng(5)
    n = 6000
    t = np.arange(n) * DT
    ring = np.zeros(n)
    for t0 in np.sort(rng.uniform(0.1, 5.9, 40)):  # a slip every 150 ms: 200 Hz, 20 ms decay
        after = t >= t0
        ring[after] += 0.4 * np.exp(-(t[after] - t0) / 0.02) * np.sin(
            2 * math.pi * 200.0 * (t[after] - t0))
    sigma = 0.002
    x = 0.3 * np.sin(2 * math.pi * 0.5 * t) + ring + rng.normal(0.0, sigma, n)
    assert N.difference_sigma(x) > 1.5 * sigma  # the ringing read as noise
    assert abs(N.white_sigma(x) / sigma - 1.0) < 0.25, N.white_sigma(x) / sigma
    e = rng.normal(0.0, sigma, n)
    for est in (N.difference_sigma, N.spectral_sigma, N.white_sigma):
        assert abs(est(e) / sigma - 1.0) < 0.1, est.__name__
