"""Every vessel config loads, holds its operating point and steers the right way; kind-specific checks of the
waterjet USV (seed 000), the Mariner (Abkowitz, MSS mariner.m) and the AUV (seed 003, REMUS stand-in). The
Nomoto kind and the linearised Nomoto parameters (study.sim.linearize) are tested in test_nomoto_kind.py.

The first call of a kind compiles its integrator (a few seconds per kind).
"""
import copy
import math

import numpy as np
import pytest

from study.configuration.compose import list_configs, read_config
from study.sim import KINDS, accelerations, load_vessel, simulate
from study.sim.effects import ShallowWater
from study.sim.linearize import linear_sway_yaw, nomoto

VESSELS = list_configs("vessel")


def _straight(duration):
    return {"name": "straight", "type": "turning", "amp_deg": 0.0, "duration": float(duration)}


# ---------------------------------------------------------------------------------------------- every vessel
def test_every_kind_has_a_config():
    kinds = {read_config("vessel", v)["kind"] for v in VESSELS}
    assert set(KINDS) <= kinds


@pytest.mark.parametrize("name", VESSELS)
def test_config_has_the_blocks_the_shared_effects_need(name):
    cfg = read_config("vessel", name)
    p = cfg["particulars"]
    for key in ("rho", "Lpp", "B", "d", "Cb", "xG"):
        assert key in p, f"{name}: particulars.{key} missing"
    assert p.get("volume") is not None or (cfg.get("mass") or {}).get("m") is not None
    assert "U0" in cfg["operation"] and "n" in cfg["operation"]
    assert set(cfg["actuator"]) >= {"rudder_rate_deg", "rudder_lag", "rudder_delay", "delta_max_deg"}
    assert set(cfg["windage"]) >= {"A_F", "A_L", "L_oa"}
    assert cfg.get("description")


@pytest.mark.parametrize("name", VESSELS)
def test_shallow_water_acts_on_the_kinds_linear_derivatives(name):
    deep = load_vessel(name)
    kind = deep.kind
    for generic, key in kind.LINEAR_DERIVATIVES.items():
        assert key in deep.cfg[kind.COEFF_SECTION], f"{name}: {kind.COEFF_SECTION}.{key} missing"
    for key in kind.ADDED_MASS_KEYS:
        assert key in deep.cfg[kind.COEFF_SECTION], f"{name}: {kind.COEFF_SECTION}.{key} missing"
    if not kind.LINEAR_DERIVATIVES:  # no hull derivatives (nomoto): shallow water is refused, not ignored
        with pytest.raises(ValueError, match="no hull derivatives"):
            load_vessel(name, [ShallowWater(h_T=1.5, formula="ankudinov")])
        return
    shallow = load_vessel(name, [ShallowWater(h_T=1.5, formula="ankudinov")])
    changed = [n for n, a, b in zip(deep.param_names, deep.params, shallow.params) if a != b]
    assert len(changed) >= 4, changed


@pytest.mark.parametrize("name", VESSELS)
def test_straight_run_holds_U0(name):
    v = load_vessel(name)
    assert np.all(np.isfinite(v.params))
    df = simulate(v, _straight(10.0 * v.L / v.U0))
    assert np.isfinite(df.to_numpy()).all()
    assert np.max(np.abs(df["u"] / v.U0 - 1.0)) < 0.01


@pytest.mark.parametrize("name", VESSELS)
def test_zigzag_turns_to_starboard_first(name):
    v = load_vessel(name)
    df = simulate(v, "zigzag_10_10", duration=10.0 + 10.0 * v.L / v.U0)
    assert np.isfinite(df.to_numpy()).all()
    rp = df["r"].to_numpy() * v.L / v.U0
    first = np.argmax(np.abs(rp) > 1e-3)
    assert rp[first] > 0, f"{name}: first yaw response {rp[first]:.2e} (r' ) is to port"
    psi = np.degrees(df["psi"].to_numpy())
    i = np.argmax(np.abs(psi) >= 5.0)
    assert psi[i] >= 5.0, f"{name}: heading reached {psi[i]:.1f} deg first"
    assert (df["u"] > 0).all()


# ------------------------------------------------------------------------------------ waterjet USV (seed 000)
@pytest.fixture(scope="module")
def usv():
    return load_vessel("usv_waterjet")


def test_usv_steady_straight_speed_is_the_seeds_start_speed(usv):
    assert usv.U0 == 0.8
    jet = usv.kind
    # the solved jet velocity zeroes the surge force at 0.8 m/s
    du, dv, dr = accelerations(usv, usv.params[:, None], *(np.array([x]) for x in (0.8, 0.0, 0.0, 0.0, usv.n0)))[0, 0]
    assert abs(du) < 1e-12 and dv == 0.0 and dr == 0.0
    assert usv.n0 == pytest.approx(jet.solve_n(usv.params[: len(jet.PARAM_NAMES)], 0.8))
    df = simulate(usv, _straight(300.0))
    assert df["u"].iloc[-1] == pytest.approx(0.8, rel=1e-9)


def test_usv_keeps_the_published_coefficients(usv):
    h = usv.cfg["hull"]
    table2 = dict(X_uu=-0.03125, X_vv=0.04657, X_rr=0.00414, Y_v=-0.27670, Y_r=0.08811, Y_vv=-1.00740,
                  Y_vr=-0.16437, Y_rr=-0.07020, N_v=0.17080, N_r=-0.05240, N_rr=-0.04350)
    assert {k: h[k] for k in table2} == table2


def test_usv_is_course_stable_with_the_published_positive_Nv(usv):
    A, b = linear_sway_yaw(usv)
    eig = np.linalg.eigvals(A)
    assert np.all(eig.real < 0), eig
    # stability index of the published hull (independent of the simulation): Y'v N'r - N'v (Y'r - m' - m'x) > 0
    h, p = usv.cfg["hull"], usv.cfg["particulars"]
    mp = usv.cfg["mass"]["m"] / (0.5 * p["rho"] * p["Lpp"] ** 2 * p["d"])
    C = h["Y_v"] * h["N_r"] - h["N_v"] * (h["Y_r"] - mp - h["m_x"])
    assert C == pytest.approx(0.0286, abs=5e-4)


def test_usv_jet_forward_of_the_neutral_point_steers_in_reverse(usv):
    """The finding behind the config's effective x_T: with N'v > 0 the sway neutral point is at N'v/Y'v L
    = -6.05 m; a jet at a plausible -4.5 m starts a starboard yaw that reverses into a steady port turn."""
    h = usv.cfg["hull"]
    assert h["N_v"] / h["Y_v"] * usv.L == pytest.approx(-6.05, abs=0.01)
    assert usv.cfg["waterjet"]["x_T"] < h["N_v"] / h["Y_v"] * usv.L  # the config's lever arm is beyond it
    cfg = copy.deepcopy(usv.cfg)
    cfg["waterjet"]["x_T"] = -4.5
    plausible = load_vessel(cfg)
    turn = {"name": "turn10", "type": "turning", "amp_deg": 10.0, "pullout_deg": 1e9, "t_start": 0.0,
            "duration": 400.0}
    df = simulate(plausible, turn)
    assert df["r"].iloc[50] > 0  # the jet's own moment first
    assert df["r"].iloc[-1] < 0  # then the hull's drift moment wins
    A, b = linear_sway_yaw(plausible)
    assert nomoto(A, b)["K"] < 0  # negative steady-state gain
    assert nomoto(*linear_sway_yaw(usv))["K"] > 0  # the config's lever arm: normal steering


# ------------------------------------------------------------------------------- Mariner (Abkowitz, mariner.m)
# test_mariner_linearised_nomoto_matches_fossen: in test_nomoto_kind.py (with study.sim.linearize)


def test_mariner_rudder_dynamics_follow_mariner_m():
    v = load_vessel("mariner")
    df = simulate(v, "zigzag_10_10", duration=60.0)
    rate = np.max(np.abs(np.diff(df["delta"].to_numpy()))) / 0.1
    assert rate <= math.radians(5.0) * (1 + 1e-9)  # 5 deg/s
    # a first-order lag (T = 1 s) behind the rate limit: the rudder reaches 10 deg later than 2 s after execute
    t_exec = 10.0
    assert np.interp(t_exec + 2.0, df.time, np.degrees(df.delta)) < 10.0 - 0.5
    assert v.cfg["actuator"]["delta_max_deg"] == 40.0


def test_mariner_propeller_asymmetry_is_kept_and_small():
    v = load_vessel("mariner")
    df = simulate(v, _straight(900.0))
    r_end = df["r"].iloc[-1]
    assert 0 < r_end < math.radians(0.2)  # Y'0, N'0 of mariner.m: a slow starboard turn with the rudder at 0
    sym = copy.deepcopy(v.cfg)
    for k in ("Y_0", "Y_0u", "Y_0uu", "N_0", "N_0u", "N_0uu"):
        sym["hull"][k] = 0.0
    df = simulate(load_vessel(sym), _straight(900.0))
    assert np.max(np.abs(df["r"])) == 0.0 and df["u"].iloc[-1] == pytest.approx(v.U0, rel=1e-12)


def test_mariner_particulars_must_agree_with_the_primes():
    cfg = copy.deepcopy(read_config("vessel", "mariner"))
    cfg["particulars"]["xG"] = 5.0
    with pytest.raises(ValueError, match="xG"):
        load_vessel(cfg)


# ------------------------------------------------------------------------------------ AUV (seed 003, REMUS)
@pytest.fixture(scope="module")
def auv():
    return load_vessel("auv")


def test_auv_turns(auv):
    turn = {"name": "turn20", "type": "turning", "amp_deg": 20.0, "pullout_deg": 1e9, "t_start": 2.0,
            "duration": 40.0}
    df = simulate(auv, turn)
    assert np.isfinite(df.to_numpy()).all()
    assert np.degrees(df["delta"].max()) == pytest.approx(20.0)
    r_end = df["r"].iloc[-1]
    assert r_end > 0.05  # rad/s, a steady starboard turn
    assert df["r"].iloc[-200:].std() < 0.01 * r_end  # settled
    assert np.degrees(df["psi"].iloc[-1]) > 360.0
    assert 0.5 * auv.U0 < df["u"].iloc[-1] < auv.U0  # slowed by the turn, still under way


def test_auv_operating_point_and_linear_instability(auv):
    assert auv.n0 == pytest.approx(15.0, rel=0.01)  # rev/s at 1.5 m/s with the assumed Q_p
    eig = np.linalg.eigvals(linear_sway_yaw(auv)[0])
    assert np.sum(eig.real > 0) == 1  # Prestero's REMUS coefficients: linearly course-unstable (see auv.yaml)


def test_auv_zigzag_stays_bounded(auv):
    df = simulate(auv, "zigzag_10_10")
    psi = np.degrees(df["psi"].to_numpy())
    assert psi.max() > 10.0 and psi.min() < -10.0
    assert np.abs(psi).max() < 60.0


# ------------------------------------------------------------------------------- stand-ins are labelled
def test_esso_osaka_is_not_a_truth():
    cfg = read_config("vessel", "esso_osaka")
    assert cfg["truth"] is False
    assert "stand-in" in cfg["description"]
