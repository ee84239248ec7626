#!/bin/bash
# After chain9 (D3's E1 cells and the first E2 cells): item 4's trace, the cell chosen by the amendment's rule from
# the records then present (/work/notes/trace_rule.py; run under `predvla trace` from a worktree at main, whose
# tracer records the errors after the iterations), then Table 2's error regression on E2 (randomised resets) for
# both PredVLA models. Two lines, one core each.
cd /work/exp84b
while [ ! -f logs/chain9.done ]; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval10_$1.log 2>&1
  echo "$(date -u) $1 rc=$?" >> logs/chain10.progress; }
(read c t < <(python /work/notes/trace_rule.py 2> logs/trace_rule.txt)
 echo "$(date -u) trace $c task $t start" >> logs/chain10.progress
 /work/notes/trace_cell.sh $c $t; echo "$(date -u) trace rc=$?" >> logs/chain10.progress
 cell table2_resets) &
cell olt_resets &
wait
date -u > logs/chain10.done
