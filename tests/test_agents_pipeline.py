"""agents.common's observation pipeline: a policy trained on stacked and normalized
observations acts, once saved and loaded, as it did behind SB3's wrappers."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from agents.common import load_config, load_policy  # noqa: E402


def test_history_and_normalized_observations_reach_the_saved_policy(tmp_path):
    """[policy] history and normalize_obs: training runs SB3's VecFrameStack and
    VecNormalize; the saved policy, loaded, takes the env's own observations and acts
    exactly as the policy does behind those wrappers, across an episode's end."""
    from agents.common import ObsPipeline, make_native_vec_env, wrap_obs
    from agents.train import train

    cfg = load_config("resonance_ppo_notorque")
    cfg["policy"].update(history=3, normalize_obs=True)
    cfg["env"]["max_episode_steps"] = 200
    cfg["train"].update(total_timesteps=512, n_envs=2, eval_freq=0, checkpoint_freq=0)
    train(cfg, tmp_path / "run", progress=False)
    model = load_policy(tmp_path / "run" / "final.zip")
    assert isinstance(model, ObsPipeline) and model.history == 3 and model.mean.shape == (30,)
    wrapped = wrap_obs(make_native_vec_env(cfg, 2), cfg, training=False)
    wrapped.obs_rms.mean, wrapped.obs_rms.var = model.mean, model.std ** 2 - 1e-8
    raw = make_native_vec_env(cfg, 2)
    wrapped.seed(5)
    raw.seed(5)
    ow, o = wrapped.reset(), raw.reset()
    start = np.ones(2, dtype=bool)
    for _ in range(60):  # 60 agent steps of 5 periods: past the 200-period episode end
        a_ref, _ = model.model.predict(ow, deterministic=True)
        a, _ = model.predict(o, episode_start=start, deterministic=True)
        assert np.array_equal(a, a_ref)
        ow, _, done_w, _ = wrapped.step(a_ref)
        o, _, start, _ = raw.step(a_ref)
        assert np.array_equal(done_w, start)
    with pytest.raises(ValueError, match="history"):
        wrap_obs(raw, {"policy": {"history": 0}})


def test_config_is_added_to_a_policy_zip_whole_or_not_at_all(tmp_path, monkeypatch):
    """embed_config appends through a copy renamed over the zip: interrupted while
    writing, the zip on disk is the one it was (and still opens); run again, it gains the
    config, once."""
    import zipfile

    from agents.common import embed_config, policy_config

    path = tmp_path / "policy.zip"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("data", "weights")
    before = path.read_bytes()

    def interrupted(self, *args, **kwargs):  # the member is written, the directory is not
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(zipfile.ZipFile, "_write_end_record", interrupted)
        with pytest.raises(KeyboardInterrupt):
            embed_config(path, {"train": {"algo": "ppo"}})
    assert path.read_bytes() == before and policy_config(path) is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.zip"]  # no temp file left
    embed_config(path, {"train": {"algo": "ppo"}})
    embed_config(path, {"train": {"algo": "sac"}})  # already there: kept
    assert policy_config(path) == {"train": {"algo": "ppo"}}
    with zipfile.ZipFile(path) as zf:
        assert zf.read("data") == b"weights"
