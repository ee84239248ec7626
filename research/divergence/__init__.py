"""Where a PredVLA checkpoint's exact open loop leaves the demonstrations, from their own starts in the simulator
(docs/research/open_loop_divergence.md): `simulation` runs and compares the rollouts, `report` writes the figures,
JSON and summary, `python -m research.divergence` is the command; `mean_plan` (`python -m
research.divergence.mean_plan`) replays the demonstrations' time-aligned mean as a plan."""
