"""Manoeuvring and prediction metrics on analytic trajectories built here (no simulator needed)."""
import math

import numpy as np
import pandas as pd
import pytest

from study.records.metrics import (detect_maneuver, prediction_metrics, standard_metrics, turning_metrics, zigzag_metrics)

D2R = math.pi / 180


def nomoto_zigzag(amp_deg=20.0, sw_deg=20.0, side=1.0, K=0.08, T=12.0, U=6.0, dt=0.05, t_start=5.0,
                  duration=400.0, rate_deg=None, psi0=0.3):
    """First-order Nomoto ship T r' + r = K delta under the IMO zigzag controller (switch on the heading
    change from the heading at execution). Returns (frame, switch indices recorded by the controller)."""
    n = int(round(duration / dt)) + 1
    amp, sw = amp_deg * D2R, sw_deg * D2R
    t = np.arange(n) * dt
    out = np.zeros((n, 5))  # r, psi, x0, y0, delta
    r = x = y = d = 0.0
    psi = psi0
    sign, started, psi_ref, switches = side, False, psi0, []
    for k in range(n):
        cmd = 0.0
        if t[k] >= t_start - 1e-9:
            if not started:
                started, psi_ref = True, psi
            if sign * (psi - psi_ref) >= sw:
                sign = -sign
                switches.append(k)
            cmd = sign * amp
        out[k] = r, psi, x, y, d
        # actuator, then semi-implicit Euler for the ship (accuracy is irrelevant: the test compares the metric
        # with a brute-force evaluation on the same samples)
        step = np.inf if rate_deg is None else rate_deg * D2R * dt
        d += float(np.clip(cmd - d, -step, step))
        r += dt * (K * d - r) / T
        x += dt * U * math.cos(psi)
        y += dt * U * math.sin(psi)
        psi += dt * r
    df = pd.DataFrame({"time": t, "u": U, "v": 0.0, "r": out[:, 0], "x0": out[:, 2], "y0": out[:, 3],
                       "psi": out[:, 1], "delta": out[:, 4], "n": 2.0})
    return df, switches, int(round(t_start / dt))


def brute_overshoots(df, switches, i_exec, sw, side):
    dpsi = df["psi"].to_numpy() - df["psi"].iloc[i_exec]
    out = []
    for k in range(len(switches) - 1):
        s = side * (-1) ** k
        out.append(math.degrees(np.max(s * dpsi[switches[k]:switches[k + 1] + 1]) - sw))
    return out


@pytest.mark.parametrize("rate_deg", [None, 2.32])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_zigzag_overshoots_match_brute_force(side, rate_deg):
    df, sws, i0 = nomoto_zigzag(side=side, rate_deg=rate_deg)
    m = zigzag_metrics(df, psi_switch=20 * D2R)
    t = df["time"].to_numpy()
    assert m["side"] == side
    assert m["execution_time"] == pytest.approx(t[i0])
    assert m["switch_times"] == pytest.approx(list(t[sws]))
    ref = brute_overshoots(df, sws, i0, 20 * D2R, side)
    assert len(ref) >= 3
    assert m["overshoots"][:len(ref)] == pytest.approx(ref, abs=1e-9)
    assert m["overshoot_1"] == pytest.approx(ref[0]) and m["overshoot_2"] == pytest.approx(ref[1])
    assert all(o > 0 for o in ref)
    # periods: first execute -> 2nd reversal, then reversal k -> k+2
    ev = [t[i0]] + list(t[sws])
    assert m["periods"] == pytest.approx([ev[k + 2] - ev[k] for k in range(len(ev) - 2)])
    assert m["period"] == pytest.approx(np.mean(m["periods"]))
    # initial turning time: the controller reverses at the first sample beyond the switch heading
    assert t[sws[0] - 1] - t[i0] <= m["initial_turning_time"] <= t[sws[0]] - t[i0] + 1e-12
    assert m["time_to_check_yaw"] == pytest.approx(m["overshoot_times"][0] - t[sws[0]])
    assert m["reach"] == pytest.approx(m["overshoot_times"][0] - t[i0])
    assert m["reach_distance"] > 0


def test_zigzag_port_and_starboard_mirror():
    a = zigzag_metrics(nomoto_zigzag(side=1.0, rate_deg=2.32)[0])
    b = zigzag_metrics(nomoto_zigzag(side=-1.0, rate_deg=2.32)[0])
    assert a["side"] == 1.0 and b["side"] == -1.0
    for k in ("overshoot_1", "overshoot_2", "overshoot_3", "period", "initial_turning_time", "time_to_check_yaw",
              "reach", "reach_distance", "psi_switch_deg"):
        assert a[k] == pytest.approx(b[k], rel=1e-9, abs=1e-9), k


def test_non_standard_zigzag_20_10_inferred_switch():
    df, sws, i0 = nomoto_zigzag(amp_deg=20, sw_deg=10, side=-1.0, rate_deg=2.32)
    given = zigzag_metrics(df, psi_switch=10 * D2R)
    assert given["psi_switch_inferred"] == 0.0
    assert given["overshoots"][:3] == pytest.approx(brute_overshoots(df, sws, i0, 10 * D2R, -1.0)[:3])
    assert given["delta_amplitude_deg"] == pytest.approx(20.0)
    inferred = zigzag_metrics(df)
    assert inferred["psi_switch_inferred"] == 1.0
    # the controller reverses at the first sample beyond 10 deg: within one step of yaw
    r_max = df["r"].abs().max()
    assert 10 <= inferred["psi_switch_deg"] <= 10 + math.degrees(r_max * 0.05) + 1e-9
    assert inferred["overshoot_1"] == pytest.approx(given["overshoot_1"], abs=math.degrees(r_max * 0.05))


def test_zigzag_short_record_gives_nan_and_errors():
    df, sws, _ = nomoto_zigzag()
    # cut before the 2nd reversal: one overshoot, no full period
    m = zigzag_metrics(df.iloc[: sws[1] - 5], psi_switch=20 * D2R)
    assert np.isfinite(m["overshoot_1"]) and math.isnan(m["overshoot_2"]) and math.isnan(m["period"])
    # cut while the heading is still moving after the 1st reversal: no overshoot yet
    m = zigzag_metrics(df.iloc[: sws[0] + 20], psi_switch=20 * D2R)
    assert math.isnan(m["overshoot_1"]) and math.isnan(m["reach"]) and m["overshoots"] == []
    with pytest.raises(ValueError, match="no rudder reversal"):
        zigzag_metrics(df.iloc[: sws[0] - 5])
    flat = df.assign(delta=0.0)
    with pytest.raises(ValueError, match="no rudder execution"):
        zigzag_metrics(flat)
    with pytest.raises(ValueError, match="lacks column"):
        zigzag_metrics(df.drop(columns="delta"))


def circle_turn(side=1.0, U=8.0, r0=0.02, t_exec=20.0, dt=0.02, duration=600.0, psi0=0.7, v_turn=0.0,
                u_turn=None, pullout_deg=None):
    """Straight run, then a rudder step with r (and optionally u, v) stepping to constants: a perfect circle.
    Positions are integrated by the trapezoidal rule on a fine grid (heading is exact)."""
    t = np.arange(int(round(duration / dt)) + 1) * dt
    after = t > t_exec
    r = np.where(after, side * r0, 0.0)
    u = np.where(after, U if u_turn is None else u_turn, U)
    v = np.where(after, -side * v_turn, 0.0)
    delta = np.where(t >= t_exec + dt / 2, side * 35 * D2R, 0.0)
    psi = psi0 + side * r0 * np.clip(t - t_exec, 0, None)
    if pullout_deg is not None:
        tp = t_exec + pullout_deg * D2R / r0
        late = t > tp
        delta[t >= tp] = 0.0
        r[late] = side * r0 * np.exp(-(t[late] - tp) / 8.0)
        psi[late] = psi0 + side * (r0 * (tp - t_exec) + r0 * 8.0 * (1 - np.exp(-(t[late] - tp) / 8.0)))
    xd = u * np.cos(psi) - v * np.sin(psi)
    yd = u * np.sin(psi) + v * np.cos(psi)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (xd[1:] + xd[:-1]) * dt)]) + 100.0
    y = np.concatenate([[0.0], np.cumsum(0.5 * (yd[1:] + yd[:-1]) * dt)]) - 50.0
    return pd.DataFrame({"time": t, "u": u, "v": v, "r": r, "x0": x, "y0": y, "psi": psi, "delta": delta,
                         "n": 2.0})


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_turning_circle_geometry(side):
    U, r0 = 8.0, 0.02
    R = U / r0
    m = turning_metrics(circle_turn(side=side, U=U, r0=r0), L=100.0)
    assert m["side"] == side
    assert m["tactical_diameter"] == pytest.approx(2 * R, rel=0.01)
    assert m["advance"] == pytest.approx(R, rel=0.01)  # circle entered tangentially: advance = transfer = R
    assert m["transfer"] == pytest.approx(R, rel=0.01)
    assert m["steady_turning_diameter"] == pytest.approx(2 * R, rel=0.01)
    assert m["steady_turning_diameter_Ur"] == pytest.approx(2 * R, rel=1e-9)
    assert m["steady_turning_rate"] == pytest.approx(r0, rel=1e-9)
    assert m["steady_turning_rate_deg"] == pytest.approx(math.degrees(r0), rel=1e-9)
    assert m["speed_loss_ratio"] == pytest.approx(1.0)
    assert m["drift_angle"] == pytest.approx(0.0, abs=1e-12)
    assert m["time_90"] == pytest.approx(math.pi / 2 / r0, abs=0.03)
    assert m["tactical_diameter_L"] == pytest.approx(m["tactical_diameter"] / 100.0)


def test_turning_port_and_starboard_mirror_with_drift_and_pullout():
    kw = dict(U=8.0, r0=0.015, u_turn=6.0, v_turn=0.6, pullout_deg=400)
    a = turning_metrics(circle_turn(side=1.0, **kw))
    b = turning_metrics(circle_turn(side=-1.0, **kw))
    for k, va in a.items():
        if k != "side":
            assert va == pytest.approx(b[k], rel=1e-9, abs=1e-9), k
    Ut = math.hypot(6.0, 0.6)
    assert a["drift_angle"] == pytest.approx(math.atan2(0.6, 6.0))  # bow into the turn: positive
    assert a["speed_loss_ratio"] == pytest.approx(Ut / 8.0)
    assert a["steady_turning_diameter"] == pytest.approx(2 * Ut / 0.015, rel=0.01)
    # the steady part ends at the pull-out (heading change 400 deg)
    assert a["steady_end_time"] == pytest.approx(20.0 + 400 * D2R / 0.015, abs=0.05)


def test_turning_errors():
    df = circle_turn()
    with pytest.raises(ValueError, match="90 deg"):
        turning_metrics(df[df["time"] < 60])
    with pytest.raises(ValueError, match="no rudder execution"):
        turning_metrics(df.assign(delta=0.0))
    short = turning_metrics(df[df["time"] < 20 + 0.75 * math.pi / 0.02])  # 135 deg: no tactical diameter
    assert np.isfinite(short["advance"]) and math.isnan(short["tactical_diameter"])


def random_rudder(seed=3, dt=0.1, duration=600.0):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration / dt) + 1) * dt
    delta = np.zeros_like(t)
    tc = 10.0
    while tc < t[-1]:
        hold = rng.uniform(10, 40)
        delta[(t >= tc) & (t < tc + hold)] = rng.uniform(-35, 35) * D2R
        tc += hold
    r = np.zeros_like(t)
    for k in range(1, len(t)):
        r[k] = r[k - 1] + dt * (0.08 * delta[k - 1] - r[k - 1]) / 12.0
    psi = np.concatenate([[0.0], np.cumsum(r[:-1] * dt)])
    return pd.DataFrame({"time": t, "u": 6.0, "v": 0.0, "r": r, "x0": 0.0, "y0": 0.0, "psi": psi,
                         "delta": delta})


def test_detect_and_dispatch():
    zz = nomoto_zigzag(rate_deg=2.32)[0]
    tc = circle_turn(pullout_deg=400)
    assert detect_maneuver(zz) == "zigzag"
    assert detect_maneuver(nomoto_zigzag(amp_deg=20, sw_deg=10, side=-1.0)[0]) == "zigzag"
    assert detect_maneuver(tc) == "turning"
    assert detect_maneuver(circle_turn(side=-1.0)) == "turning"
    assert detect_maneuver(random_rudder()) == "other"
    assert detect_maneuver(zz.assign(delta=0.0)) == "other"
    sz = standard_metrics(zz, L=50.0)
    assert sz["maneuver"] == "zigzag" and sz["overshoot_1"] == pytest.approx(zigzag_metrics(zz)["overshoot_1"])
    assert "reach_distance_L" in sz
    st = standard_metrics(tc, L=100.0)
    assert st["maneuver"] == "turning" and "tactical_diameter_L" in st
    assert standard_metrics(random_rudder()) == {"maneuver": "other"}


def test_prediction_metrics_identical_and_offset():
    df = nomoto_zigzag(duration=200.0)[0]
    m = prediction_metrics(df, df.copy())
    for c in ("u", "v", "r", "psi"):
        assert m[f"rmse_{c}"] == 0.0 and m[f"max_abs_error_{c}"] == 0.0
    for c in ("r", "psi"):
        assert m[f"cc_{c}"] == pytest.approx(1.0)
    assert math.isnan(m["cc_u"])  # constant measured channel: correlation undefined
    assert m["track_rmse"] == 0.0 and m["final_position_error"] == 0.0

    pred = df.assign(r=df["r"] + 0.001, x0=df["x0"] + 3.0, y0=df["y0"] - 4.0)
    m = prediction_metrics(df, pred)
    assert m["rmse_r"] == pytest.approx(0.001) and m["max_abs_error_r"] == pytest.approx(0.001)
    assert m["nrmse_r"] == pytest.approx(0.001 / df["r"].std(ddof=0))
    assert m["cc_r"] == pytest.approx(1.0)
    assert m["track_rmse"] == pytest.approx(5.0) and m["final_position_error"] == pytest.approx(5.0)

    # predicted on a finer grid: interpolated onto the measured time stamps (linear signals stay exact)
    t = np.linspace(0, 100, 1001)
    meas = pd.DataFrame({"time": t[::10], "u": 2 * t[::10], "v": 0.0, "r": t[::10] ** 0, "psi": -t[::10]})
    pred = pd.DataFrame({"time": t, "u": 2 * t + 1, "v": 0.0, "r": 1.0, "psi": -t})
    m = prediction_metrics(meas, pred)
    assert m["rmse_u"] == pytest.approx(1.0) and m["rmse_psi"] == pytest.approx(0.0, abs=1e-12)
    assert "track_rmse" not in m
    with pytest.raises(ValueError, match="lacks column"):
        prediction_metrics(meas, pred.drop(columns="r"))
    with pytest.raises(ValueError, match="fewer than 2"):
        prediction_metrics(meas, pred.assign(time=pred["time"] + 1000))


def test_noisy_rudder_record_still_finds_execution_and_reversals():
    # delta noise (0.5 deg) larger than the 0.5 deg threshold and than the ramp step per sample (0.12 deg)
    df, sws, i0 = nomoto_zigzag(rate_deg=2.32)
    t = df["time"].to_numpy()
    noisy = df.assign(delta=df["delta"] + 0.5 * D2R * np.random.default_rng(0).standard_normal(len(df)))
    assert detect_maneuver(noisy) == "zigzag"
    m = zigzag_metrics(noisy, psi_switch=20 * D2R)
    assert m["execution_time"] == pytest.approx(t[i0], abs=0.5)
    assert m["switch_times"] == pytest.approx(list(t[sws]), abs=0.5)
    clean = zigzag_metrics(df, psi_switch=20 * D2R)
    assert m["overshoot_1"] == pytest.approx(clean["overshoot_1"], abs=0.2)
