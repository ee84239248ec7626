"""LIBERO: installation, tasks and rendering, scripted expert, demonstration recording and replay, and the
`--env.type=predvla_libero` env type LeRobot evaluates in (`env_config.py`; the gym env, `predvla_libero.py`, is
loaded only once an env is built)."""
