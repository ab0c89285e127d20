"""hdgym: harmonic-drive joint simulator, Gymnasium environments and tools."""

from hdgym.envs import register_envs as _register_envs

_register_envs()
