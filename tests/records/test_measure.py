"""Measurement model: reproducibility, noise statistics, coloured noise, outliers, dropouts, sampling.

Statistical tolerances are 5 standard errors of the tested estimator at the sample size used (stated at each
check), so a correct implementation fails with probability < 1e-6 per check; the seeds are fixed anyway.
"""
import math

import numpy as np
import pandas as pd
import pytest

from study.records.measure import DEFAULT_CHANNELS, MeasurementModel, resample

N = 20001


def clean(n=N, dt=0.1, t0=0.0):
    t = t0 + np.arange(n) * dt
    w = 2 * np.pi / 300.0
    return pd.DataFrame({
        "time": t,
        "u": 7.0 + 0.5 * np.cos(w * t),
        "v": 0.3 * np.sin(w * t),
        "r": 0.01 * np.cos(w * t),
        "x0": 1000.0 + 7.0 * t,  # large offsets: the scale must not depend on them
        "y0": -500.0 + 50.0 * np.sin(w * t),
        "psi": 2.0 + 0.3 * np.sin(w * t),
        "delta": 0.35 * np.sign(np.sin(w * t)),
        "n": 1.5,
    })


def test_reproducible_and_seed_dependent():
    df = clean(2001)
    kw = dict(noise_level=0.05, colored={"tau": 5.0, "level": 0.02}, outliers={"prob": 0.01, "size": 5.0},
              dropouts={"prob": 0.02, "burst": 3})
    m = MeasurementModel(seed=7, **kw)
    a, b = m.apply(df), m.apply(df)
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(a, MeasurementModel(seed=7, **kw).apply(df))
    c = MeasurementModel(seed=8, **kw).apply(df)
    assert len(a) != len(c) or not np.allclose(a["u"], c["u"])
    a0, c0 = (MeasurementModel(seed=s, noise_level=0.05).apply(df) for s in (7, 8))
    assert not np.any(a0["u"].to_numpy() == c0["u"].to_numpy())


def test_channel_streams_are_independent_of_the_channel_set():
    df = clean(2001)
    base = MeasurementModel(noise_level=0.05, seed=3).apply(df)
    more = MeasurementModel(noise_level=0.05, seed=3, channels=DEFAULT_CHANNELS + ("n",)).apply(df)
    fewer = MeasurementModel(noise_level=0.05, seed=3, channels=("psi", "u")).apply(df)
    for c in ("u", "psi"):
        np.testing.assert_array_equal(base[c], more[c])
        np.testing.assert_array_equal(base[c], fewer[c])
    assert not np.array_equal(more["n"], df["n"])
    # switching on outliers does not change the white noise draws
    with_out = MeasurementModel(noise_level=0.05, seed=3, outliers={"prob": 0.0, "size": 5.0}).apply(df)
    pd.testing.assert_frame_equal(base, with_out)


def test_white_noise_level_per_channel():
    df = clean()
    level = 0.05
    m = MeasurementModel(noise_level=level, seed=11)
    noisy = m.apply(df)
    S = m.scales(df)
    # offset channels: RMS of the deviation from the mean
    assert S["x0"] == pytest.approx(df["x0"].std(ddof=0)) and S["psi"] == pytest.approx(df["psi"].std(ddof=0))
    assert S["u"] == pytest.approx(math.sqrt(np.mean(df["u"] ** 2)))
    # sample std of N Gaussian draws: relative standard error 1/sqrt(2(N-1)) = 0.5 %; tolerance 5 SE
    tol = 5 / math.sqrt(2 * (N - 1))
    for c in DEFAULT_CHANNELS:
        e = (noisy[c] - df[c]).to_numpy() / S[c]
        assert np.std(e) / level == pytest.approx(1.0, abs=tol), c
        assert abs(np.mean(e)) < 5 * level / math.sqrt(N), c  # zero mean: SE = level / sqrt(N)
    np.testing.assert_array_equal(noisy["n"], df["n"])  # not a measured channel: untouched
    # per-channel dict: only the named channel gets noise
    only_r = MeasurementModel(noise_level={"r": 0.1}, seed=11).apply(df)
    assert np.std((only_r["r"] - df["r"]) / S["r"]) == pytest.approx(0.1, rel=tol)
    np.testing.assert_array_equal(only_r["u"], df["u"])


def test_colored_noise_is_ar1_with_the_requested_correlation():
    dt, tau, level = 1.0, 5.0, 0.05
    df = clean(dt=dt)
    m = MeasurementModel(colored={"tau": tau, "level": level}, seed=5)
    noisy = m.apply(df)
    S = m.scales(df)
    phi = math.exp(-dt / tau)
    for c in ("u", "r", "psi"):
        e = (noisy[c] - df[c]).to_numpy() / S[c]
        e0 = e - e.mean()
        rho1 = np.sum(e0[1:] * e0[:-1]) / np.sum(e0 ** 2)
        # lag-1 autocorrelation of an AR(1): SE ~ sqrt((1 - phi^2) / N) = 0.004; tolerance 5 SE
        assert rho1 == pytest.approx(phi, abs=5 * math.sqrt((1 - phi ** 2) / N)), c
        # std: effective sample size N (1 - phi) / (1 + phi) ~ 2000 -> relative SE 1.6 %; tolerance 5 SE
        n_eff = N * (1 - phi) / (1 + phi)
        assert np.std(e) / level == pytest.approx(1.0, abs=5 / math.sqrt(2 * n_eff)), c


def test_colored_noise_on_irregular_time_stamps():
    df = clean(dt=1.0)
    df["time"] += np.random.default_rng(0).uniform(-0.01, 0.01, len(df))  # irregular: exact GM recursion
    noisy = MeasurementModel(colored={"tau": 5.0, "level": 0.05}, seed=5).apply(df)
    e = (noisy["u"] - df["u"]).to_numpy()
    e0 = e - e.mean()
    phi = math.exp(-1.0 / 5.0)
    assert np.sum(e0[1:] * e0[:-1]) / np.sum(e0 ** 2) == pytest.approx(phi, abs=5 * math.sqrt((1 - phi ** 2) / N))


def test_dropouts_independent_and_bursts():
    df = clean()
    p = 0.05
    out = MeasurementModel(dropouts={"prob": p}, seed=2).apply(df)
    # binomial fraction: SE sqrt(p (1 - p) / N) = 0.0015; tolerance 5 SE
    assert 1 - len(out) / N == pytest.approx(p, abs=5 * math.sqrt(p * (1 - p) / N))
    assert not out.isna().any().any() and out.index.equals(pd.RangeIndex(len(out)))
    kept = df.set_index("time").loc[out["time"]].reset_index()
    pd.testing.assert_frame_equal(out, kept[out.columns])  # rows removed, the others exact

    b = 4.0
    outb = MeasurementModel(dropouts={"prob": p, "burst": b}, seed=2).apply(df)
    lost = ~np.isin(df["time"], outb["time"])
    # Gilbert chain: the fraction's variance is inflated by (1 + lam) / (1 - lam), lam = 1 - 1/b - p/((1-p) b)
    lam = 1 - 1 / b - p / ((1 - p) * b)
    se = math.sqrt(p * (1 - p) / N * (1 + lam) / (1 - lam))
    assert lost.mean() == pytest.approx(p, abs=5 * se)
    edges = np.diff(np.concatenate([[0], lost.astype(int), [0]]))
    runs = np.nonzero(edges == -1)[0] - np.nonzero(edges == 1)[0]
    # burst lengths are geometric with mean b, sd sqrt(1 - 1/b) b; ~250 bursts; tolerance 5 SE
    assert runs.mean() == pytest.approx(b, abs=5 * math.sqrt(1 - 1 / b) * b / math.sqrt(len(runs)))
    # burst length given in seconds
    outs = MeasurementModel(dropouts={"prob": p, "burst_s": 0.4}, seed=2).apply(df)
    pd.testing.assert_frame_equal(outs, outb)
    with pytest.raises(ValueError, match="burst"):
        MeasurementModel(dropouts={"prob": 0.9, "burst": 2}).apply(df)


@pytest.mark.parametrize("scale", ["sigma", "rms"])
def test_outlier_rate_and_size(scale):
    df = clean()
    p, size, level = 0.01, 20.0, 0.01
    m = MeasurementModel(noise_level=level, outliers={"prob": p, "size": size, "scale": scale}, seed=4)
    noisy = m.apply(df)
    S = m.scales(df)
    hits, total = 0, 0
    for c in DEFAULT_CHANNELS:
        e = (noisy[c] - df[c]).to_numpy() / (level * S[c])  # in white-noise sigmas
        spike = size if scale == "sigma" else size / level
        big = np.abs(e) > spike / 2  # white noise never reaches 10 sigma
        assert np.all(np.abs(np.abs(e[big]) - spike) < 6), c  # spike +- white noise
        hits += big.sum()
        total += len(e)
    # binomial count over 7 x N samples: SE sqrt(p (1 - p) / total); tolerance 5 SE
    assert hits / total == pytest.approx(p, abs=5 * math.sqrt(p * (1 - p) / total))


def test_zero_noise_is_exact_and_sampling():
    df = clean(2001)
    pd.testing.assert_frame_equal(MeasurementModel().apply(df), df)
    pd.testing.assert_frame_equal(MeasurementModel(dt=0.1).apply(df), df)
    # coarser multiple: exact source rows (times as in the source, no rounding of t0 + k dt)
    out = MeasurementModel(dt=0.3).apply(df)
    pd.testing.assert_frame_equal(out, df.iloc[::3].reset_index(drop=True))
    # not a multiple: linear interpolation (exact on linear columns)
    out = resample(df, 0.25)
    assert out["time"].iloc[1] == pytest.approx(0.25) and len(out) == 801
    np.testing.assert_allclose(out["x0"], 1000.0 + 7.0 * out["time"], rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="finer"):
        MeasurementModel(dt=0.05).apply(df)


def test_bias_and_input_not_modified():
    df = clean(2001)
    before = df.copy(deep=True)
    m = MeasurementModel(dt=0.2, noise_level={"u": 0.02}, bias={"r": 0.001, "psi": -0.02},
                         colored={"tau": 3.0, "level": 0.01}, outliers={"prob": 0.01, "size": 5.0},
                         dropouts={"prob": 0.05}, seed=1)
    out = m.apply(df)
    pd.testing.assert_frame_equal(df, before)
    assert list(out.columns) == list(df.columns) and not out.isna().any().any()
    only_bias = MeasurementModel(bias={"r": 0.001}).apply(df)
    np.testing.assert_allclose(only_bias["r"] - df["r"], 0.001, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="bias"):
        MeasurementModel(bias={"n": 1.0}).apply(df)
    with pytest.raises(ValueError, match="lacks column"):
        MeasurementModel().apply(df.drop(columns="psi"))
    with pytest.raises(ValueError, match="tau"):
        MeasurementModel(colored={"level": 0.02}).apply(df)
