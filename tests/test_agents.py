"""agents/: the committed policy crosses the resonance trap; training and evaluation run."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from agents.baselines import ConstantCurrent, PISpeedController, design_pi  # noqa: E402
from agents.common import env_kwargs, load_config, load_policy, make_env, policy_config  # noqa: E402,E501
from agents.evaluate import controller_period, evaluate  # noqa: E402
from agents.evaluate import main as evaluate_main  # noqa: E402
from agents.families import FamilyController, ke_grid  # noqa: E402
from agents.front import main as front_main  # noqa: E402
from agents.front import run_grid, success, wilson  # noqa: E402
from agents.train import main as train_main  # noqa: E402
from agents.vec_env import HarmonicDriveVecEnv  # noqa: E402
from hdgym.envs.resonance import DEFAULT_CURRENT_LIMIT, TRAP_ONLY_CURRENT_LIMIT  # noqa: E402
from hdgym.params import preset  # noqa: E402

POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "resonance_ppo.zip"


def test_committed_policy_is_small_and_carries_its_config():
    assert POLICY.is_file()
    assert POLICY.stat().st_size < 1_000_000
    cfg = policy_config(POLICY)
    assert cfg["env"]["id"] == "HarmonicDriveResonance-v0"
    # the task as registered: the preset's amplifier, the env's rating and deadline
    kw = cfg["env"]["kwargs"]
    assert kw.get("current_limit", DEFAULT_CURRENT_LIMIT) is None
    assert "torque_limit" not in kw and "deadline" not in kw
    assert set(kw["randomize"]) >= {
        "compliance.stiffness", "friction.output.coulomb", "kinematic_error.amplitude"}
    nt = policy_config(POLICY.with_name("resonance_ppo_notorque.zip"))
    assert nt["env"]["id"] == "HarmonicDriveResonanceNoTorqueSensor-v0"


def test_committed_policy_succeeds_where_brute_force_breaks_the_rating():
    """The registered task, 6 randomized episodes: the committed policy reaches the target
    by the deadline within the rating; constant full current is faster but exceeds the
    rating and fails every episode."""
    model = load_policy(POLICY)
    cfg = policy_config(POLICY)
    stats, traces = evaluate(cfg, ["policy", "full"], 6, 4242, model)
    pol, full = stats
    assert pol.success >= 4 / 6
    assert full.success == 0.0 and full.terminated == 1.0
    assert np.max(traces["full"]["current"]) <= 6.0 + 1e-9


def test_trap_only_variant_traps_full_current_and_pi():
    """``current_limit=3.7``: full current and the saturated PI stay trapped (4 episodes)."""
    cfg = policy_config(POLICY)
    cfg["env"]["kwargs"]["current_limit"] = TRAP_ONLY_CURRENT_LIMIT
    stats, traces = evaluate(cfg, ["full", "pi"], 4, 4242)
    for s in stats:
        assert s.trapped == 1.0 and s.reached == 0.0, s.controller
    # the amplifier saturates at the variant's limit: nobody draws more
    for tr in traces.values():
        assert np.max(tr["current"]) <= TRAP_ONLY_CURRENT_LIMIT + 1e-9


def test_classical_controllers_act_every_period_and_the_policy_holds():
    cfg = load_config("resonance_ppo")
    assert controller_period("policy", cfg) == cfg["env"]["action_repeat"] == 5
    for name in ("pi", "full", "damp@0.1,90", "ripple@0.1,0", "const@4A"):
        assert controller_period(name, cfg) == 1


def _family(name, params, n=1):
    p = preset("tuttle-joint1")
    ctl = FamilyController(name, params, p, speed_scale=700.0, dt=1e-3)
    ctl.reset(n)
    return ctl, p


def test_ramp_pi_follows_its_own_clock_and_two_phase_switches():
    """pi_ramp's reference min(target, rate t) runs on the controller's clock, also past 3 s
    where the time observation saturates (the long variant's episodes last 6 s)."""
    ctl, p = _family("pi_ramp", {"rate": 100.0, "limit": 6.0}, 1)
    obs = np.zeros((1, 10))
    obs[:, 6] = 500.0 / 700.0  # target 500 rad/s
    obs[:, 0] = 320.0 / 500.0  # speed 320 rad/s: the reference passes it at 3.2 s
    obs[:, 9] = 1.0  # the time observation, saturated: not used
    u = [ctl.command(obs)[0] for _ in range(3500)]  # 3.5 s of 1 ms calls
    assert ctl.t[0] == pytest.approx(3.5)
    assert u[3000] < 0.0 < u[3499] <= 6.0
    ctl, _ = _family("two_phase", {"run": 6.0, "switch": 150.0, "hold": 3.9}, 2)
    obs = np.zeros((2, 10))
    obs[:, 6] = 200.0 / 700.0  # target 200 rad/s
    obs[:, 0] = [0.5, 0.9]  # 100 and 180 rad/s: below and above the switch
    u = ctl.command(obs)
    assert u[0] == 6.0 and u[1] <= 3.9 + 1e-12
    obs[:, 0] = 0.5  # back below the switch: the hold phase stays on
    assert ctl.command(obs)[1] <= 3.9 + 1e-12


def test_ke_grid_adds_a_ripple_on_top_of_a_pick():
    pts = ke_grid({"level": 4.0}, 6.0)
    assert pts[0]["ke_amp"] == 0.0 and len(pts) == 1 + 3 * 8
    ctl, _ = _family("const", {"level": 4.0, "ke_amp": 0.3, "ke_phase": 0.0}, 2)
    obs = np.zeros((2, 10))
    obs[:, 2] = [1.0, 0.0]  # WG angle 0 and 90 deg: cos(2 theta) = 1, -1
    obs[:, 3] = [0.0, 1.0]
    assert ctl.command(obs) == pytest.approx([4.3, 3.7])


def test_front_success_and_wilson_interval():
    ttt = np.array([1.0, 1.9, np.nan, 2.5])
    peak = np.array([150.0, 210.0, 100.0, 150.0])
    assert success(ttt, peak, 200.0, 2.0).tolist() == [True, False, False, False]
    assert success(ttt, peak, 250.0, 3.0).tolist() == [True, True, False, True]
    lo, hi = wilson(9, 10)
    assert 0.55 < lo < 0.9 < hi <= 1.0
    assert wilson(0, 20)[0] == 0.0


def test_grid_runs_as_one_batch_on_the_same_episodes():
    """Two constant currents on the same 3 episodes: full current gets to the target in
    each, with more torque than 4.5 A, whose reach (if any) is later."""
    cfg = load_config("resonance_ppo")
    cfg["env"]["max_episode_steps"] = 2500
    res = run_grid(cfg, "const", [{"level": 4.5}, {"level": 6.0}], [7, 8, 9])
    assert res["time_to_target"].shape == (2, 3)
    assert np.isfinite(res["time_to_target"][1]).all()
    assert not np.any(res["time_to_target"][0] <= res["time_to_target"][1])
    assert np.all(res["peak_torque"][1] > res["peak_torque"][0])
    assert not res["terminated"].any()  # the front runs without the rating


def test_front_cli_quick_writes_json_and_refuses_bad_input(tmp_path, capsys):
    out = tmp_path / "front.json"
    assert front_main(["--quick", "--families", "const", "--train", "2", "--test", "3",
                       "--out", str(out)]) == 0
    import json

    f = json.loads(out.read_text())
    assert set(f["families"]) == {"const"}
    assert f["test_seeds"] == [100_000, 3]
    assert front_main(["--families", "nope", "--quick"]) == 2
    assert "unknown" in capsys.readouterr().err


def test_pi_design_meets_its_specification():
    d = design_pi(preset("tuttle-joint1"), crossover_hz=5.0, phase_margin_deg=60.0)
    assert d.kp > 0 and d.ki > 0
    assert math.isclose(d.achieved_pm_deg, 60.0, abs_tol=0.5)
    assert math.isclose(d.achieved_crossover_hz, 5.0, rel_tol=0.02)
    with pytest.raises(ValueError, match="phase margin"):
        design_pi(preset("tuttle-joint1"), crossover_hz=5.0, phase_margin_deg=120.0)


def test_pi_anti_windup_respects_the_limits():
    p = preset("tuttle-joint1")
    pi = PISpeedController(p, target_scale=800.0, dt=1e-3, current_limit=4.0)
    obs = np.zeros((3, 10), dtype=np.float32)
    obs[:, 6] = 0.25  # target 200 rad/s
    obs[:, 0] = [0.0, 0.5, 1.5]  # speed / target
    for _ in range(2000):
        a, _ = pi.predict(obs)
    amps = a[:, 0] * p.amplifier.current_limit
    assert amps[0] == pytest.approx(4.0) and amps[1] == pytest.approx(4.0)
    assert amps[2] < 0
    # the integrator did not wind up: one step with zero error leaves only the clipped value
    assert np.all(np.abs(pi.integral) < 10.0)
    c, _ = ConstantCurrent(0.5).predict(obs)
    assert c.shape == (3, 1) and np.all(c == 0.5)


def test_smoke_training_ppo(tmp_path):
    out = tmp_path / "ppo"
    rc = train_main(["--algo", "ppo", "--total-timesteps", "2000", "--n-envs", "2",
                     "--seed", "3", "--out", str(out), "--no-progress"])
    assert rc == 0
    assert (out / "final.zip").is_file() and (out / "train.json").is_file()
    assert list((out / "monitor").glob("*.monitor.csv"))
    assert list((out / "tb").iterdir())
    model = load_policy(out / "final.zip")
    cfg = policy_config(out / "final.zip")
    assert cfg["train"]["seed"] == 3
    env = make_env(cfg)
    obs, _ = env.reset(seed=0)
    a, _ = model.predict(obs, deterministic=True)
    assert a.shape == (1,)


def test_smoke_training_sac(tmp_path):
    cfg = load_config("resonance_sac")
    assert cfg["train"]["algo"] == "sac"
    out = tmp_path / "sac"
    rc = train_main(["--algo", "sac", "--total-timesteps", "300", "--n-envs", "1",
                     "--out", str(out), "--no-progress"])
    assert rc == 0 and (out / "final.zip").is_file()
    assert policy_config(out / "final.zip")["train"]["algo"] == "sac"


def test_cli_errors_exit_2(tmp_path, capsys):
    assert evaluate_main(["--policy", str(tmp_path / "missing.zip")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert train_main(["--config", str(tmp_path / "nope.toml"), "--no-progress"]) == 2
    assert train_main(["--config", "resonance_sac", "--algo", "ppo", "--no-progress"]) == 2


def test_sb3_vec_env_trains_and_reports_episode_ends():
    """The SB3 VecEnv hands SB3 the native batch: terminal observations, truncation flags
    and seeds follow SB3's conventions, and PPO runs on it."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    venv = HarmonicDriveVecEnv("HarmonicDriveJoint-v0", num_envs=4, max_episode_steps=20,
                               preset="tuttle-joint1")
    venv.seed(7)
    first = venv.reset()
    venv.seed(7)
    np.testing.assert_array_equal(venv.reset(), first)
    single = gym.make("HarmonicDriveJoint-v0", preset="tuttle-joint1", max_episode_steps=20)
    np.testing.assert_array_equal(first[2], single.reset(seed=9)[0])
    acts = np.zeros((4, 1), dtype=np.float32)
    for _ in range(20):
        obs, rew, dones, infos = venv.step(acts)
        assert rew.shape == (4,) and dones.dtype == np.bool_ and len(infos) == 4
    assert dones.all()  # every episode truncated at 20 steps
    assert all(info["TimeLimit.truncated"] for info in infos)
    assert all(venv.observation_space.contains(info["terminal_observation"]) for info in infos)
    assert not np.array_equal(infos[0]["terminal_observation"], obs[0])  # obs is the new one
    assert venv.get_attr("num_envs") == [4] * 4 and venv.env_is_wrapped(VecMonitor) == [False] * 4
    model = PPO("MlpPolicy", VecMonitor(venv), n_steps=32, batch_size=64, n_epochs=1, seed=0)
    model.learn(256)
    assert model.num_timesteps >= 256
    venv.close()



def test_sb3_vec_env_rejects_its_fixed_autoreset():
    with pytest.raises(ValueError, match="autoreset_mode"):
        HarmonicDriveVecEnv("HarmonicDriveJoint-v0", num_envs=2, autoreset_mode="next_step")


def test_native_hold_and_penalty_match_the_wrapped_single_env():
    """Action repeat and torque penalty inside the batch give env i the rewards, ends and
    observations of the wrapped single env (ActionRepeat + TorquePenalty) seeded s + i; an
    env whose episode ends inside a hold stops there and restarts at the next agent step."""
    cfg = load_config("resonance_ppo")
    cfg["env"]["max_episode_steps"] = 23  # not a multiple of the hold: ends mid-hold
    venv = HarmonicDriveVecEnv(cfg["env"]["id"], num_envs=2, action_repeat=5,
                               torque_penalty=(2.0, 20.0), max_episode_steps=23,
                               **env_kwargs(cfg))
    cfg["env"]["torque_penalty"] = {"weight": 2.0, "threshold": 20.0}
    singles = [make_env(cfg) for _ in range(2)]
    venv.seed(5)
    obs = venv.reset()
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=5 + i)
        np.testing.assert_array_equal(o, obs[i])
    acts = np.array([[1.0], [0.6]], dtype=np.float32)
    ends = 0
    for _ in range(6):
        obs, rew, done, infos = venv.step(acts)
        for i, env in enumerate(singles):
            o, r, term, trunc, _ = env.step(acts[i])
            assert r == pytest.approx(rew[i], rel=1e-6)
            assert done[i] == (term or trunc)
            if done[i]:
                ends += 1
                np.testing.assert_array_equal(o, infos[i]["terminal_observation"])
                assert infos[i]["TimeLimit.truncated"] and "is_success" in infos[i]
                o, _ = env.reset()
                assert np.isclose(obs[i][9], 0.0)  # the batch restarted it: time 0
            else:
                np.testing.assert_array_equal(o, obs[i])
    assert ends == 2
    with pytest.raises(ValueError, match="action_repeat"):
        HarmonicDriveVecEnv(cfg["env"]["id"], num_envs=1, action_repeat=0)


def test_report_refuses_quick_runs_into_results(capsys):
    from agents.report import main as report_main

    assert report_main(["--quick", "--out", "results/rl"]) == 2
    assert "results" in capsys.readouterr().err


@pytest.mark.slow
def test_report_quick_writes_the_page(tmp_path):
    """The whole report on small grids and 8 episodes (a few minutes)."""
    from agents.report import main as report_main

    assert report_main(["--quick", "--out", str(tmp_path / "rl")]) == 0
    page = (tmp_path / "rl" / "evaluation.md").read_text()
    assert "Quick smoke-test run" in page and "HarmonicDriveResonanceNoTorqueSensor-v0" in page
    assert (tmp_path / "rl" / "front.png").is_file()


# ------------------------------------------------------------ the rules: rating and deadline
def _front(train: dict[str, list[list[float]]], caps: list[float],
           deadlines: list[float]) -> dict:
    """A front with given training success per family, deadline and cap."""
    return {"caps": caps, "deadlines": deadlines, "families": {
        name: {"front": [[{"train": s} for s in row] for row in rows]}
        for name, rows in train.items()}}


def test_rules_pick_deadline_then_rating_from_the_training_front():
    from agents.rules import (
        RATED_MAXIMUM,
        check_constants,
        long_deadline_rule,
        rating_rule,
        rules,
    )

    caps, deadlines = [180.0, 190.0, 200.0, 400.0], [2.0, 2.5, 3.0]
    f = _front({"const": [[0.0, 0.1, 0.2, 0.85], [0.1, 0.2, 0.3, 0.95], [0.2, 0.3, 0.4, 1.0]],
                "damp": [[0.3, 0.6, 0.7, 1.0], [0.4, 0.5, 0.8, 1.0], [0.5, 0.7, 0.9, 1.0]],
                # KE feedforward takes no part: tuned at the rating and deadline
                "damp+ke": [[1.0] * 4] * 3}, caps, deadlines)
    # the long front (the Long variant's episodes): best success at the rating (190 N m)
    # by deadline 2.5, 3, 3.5, 4, 4.5 s is 0.5, 0.6, 0.8, 0.97, 0.98 (ramp) or less (const)
    longf = _front({"ramp": [[0.0, s, 0.0, 1.0] for s in (0.5, 0.6, 0.8, 0.97, 0.98)],
                    "const": [[0.0, 0.3, 0.0, 1.0]] * 5,
                    "ramp+ke": [[1.0] * 4] * 5}, caps, [2.5, 3.0, 3.5, 4.0, 4.5])
    longf["train_seeds"] = [0, 64]
    r = rules(f, longf)
    # 2 s: const reaches only 85 % uncapped; 2.5 s: every family >= 90 %
    assert r["deadline"] == 2.5 and r["uncapped_train_success"] == {"const": 0.95, "damp": 1.0}
    assert r["rating"] == 190.0  # first cap with best >= 50 %
    assert r["best_train_success"][180.0] == 0.4
    # 4 s: within one training episode (1/64) of the 4.5 s best, 3.5 s is not
    assert r["long_deadline"] == 4.0 and r["long_best_train_success"][3.5] == 0.8
    assert rules(f)["long_deadline"] is None
    have = {"deadline": 2.5, "rating": 190.0, "long_deadline": 4.0}
    assert check_constants(r, have) == []
    assert check_constants(r, {"deadline": 2.0, "rating": 200.0, "long_deadline": 3.0}) == [
        "DEADLINE = 2.5", 'GEAR_RATINGS["tuttle-joint1"] = 190.0', "LONG_DEADLINE = 4.0"]
    # still growing at the long front's last deadline: the long episode is too short
    growing = _front({"ramp": [[0.0, s, 0.0, 1.0] for s in (0.5, 0.6, 0.8, 0.9, 0.99)]},
                     caps, [2.5, 3.0, 3.5, 4.0, 4.5])
    with pytest.raises(ValueError, match="still grows"):
        long_deadline_rule(growing, 190.0, 2.5)
    # more time does not help: the long deadline would not be longer than the deadline
    flat = _front({"ramp": [[0.0, 0.6, 0.0, 1.0]] * 3}, caps, [2.5, 3.0, 3.5])
    with pytest.raises(ValueError, match="not longer"):
        long_deadline_rule(flat, 190.0, 2.5)
    # a rating above the drive's rated maximum (~286 N m) is refused
    high = _front({"const": [[0.1, 0.2, 0.3, 0.9]]}, [200.0, 250.0, 300.0, 400.0], [2.0])
    assert RATED_MAXIMUM == pytest.approx(285.7, abs=0.1)
    with pytest.raises(ValueError, match="rated maximum"):
        rating_rule(high, 2.0)
    with pytest.raises(ValueError, match="no deadline"):
        rules(_front({"const": [[0.1, 0.2, 0.3, 0.5]]}, caps, [2.0]))


def test_committed_front_and_registered_constants_follow_the_rules():
    """results/rl/front.json (the committed front) gives, by the rules, exactly the
    registered deadline, long deadline and rating, and the page was made with them."""
    import json

    from agents.rules import check_constants, registered, rules

    res = Path(__file__).resolve().parents[1] / "results" / "rl"
    fronts = json.loads((res / "front.json").read_text())
    ruled = rules(fronts["HarmonicDriveResonance-v0"], fronts["HarmonicDriveResonanceLong-v0"])
    assert check_constants(ruled) == [], "set these in hdgym/envs/resonance.py"
    ev = json.loads((res / "evaluation.json").read_text())
    reg = registered()
    assert ev["rules"]["deadline"] == reg["deadline"] and ev["rules"]["rating"] == reg["rating"]
    assert ev["rules"]["long_deadline"] == reg["long_deadline"]
    for name, v in ev["variants"].items():
        assert v["rating"] == reg["rating"]
        assert v["deadline"] == (reg["long_deadline"] if "Long" in name else reg["deadline"])


def test_benchmark_quick_runs_the_pipeline(tmp_path):
    """agents.benchmark --quick: small fronts, the rules, KE, the page (no training here)."""
    from agents.benchmark import main as bench_main

    work = tmp_path / "work"
    assert bench_main(["--quick", "--skip-train", "--fronts-dir", str(work)]) == 0
    page = (work / "evaluation.md").read_text()
    assert "Quick smoke-test run" in page and "agents.rules.rating_rule" in page
    for var in ("HarmonicDriveResonance-v0", "HarmonicDriveResonanceLong-v0",
                "HarmonicDriveResonanceNoTorqueSensor-v0"):
        assert (work / f"front_{var}_ke.json").is_file()
    assert bench_main(["--quick", "--out", "results/rl"]) == 2  # never into results/
