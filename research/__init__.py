"""The research diagnostics behind docs/research/: each module or folder reproduces a write-up's figures and tables
with `python -m research.<name>` from the repository root. Not part of the installed package (`pip install .` ships
`lerobot_predvla` and `lerobot_policy_predvla` only); it imports `lerobot_predvla`, never the reverse
(tests/test_layering.py).

- `divergence`: the exact open loop against the demonstrations from their own starts (simulator, physics only).
- `er_correction`: error regression's correction before the grasp against the scripted expert's (traces, simulator).
- `er_timing`: when error regression starts the plan's lift against the open loop, and the outcomes (traces).
- `mechanism`: error regression on a reach task only observations can solve (no simulator).
- `oracle_probe`: a linear probe of the visual features for object poses beyond proprioception (simulator states).
"""
