#!/bin/bash
# After chain10's first line (Table 2 literal's Table 2 ER on D3's E2): the exact open loop of the traced cell's model
# on the same task traced once (one episode: in exact open loop every official init state gets the same actions), so
# that `research.er_timing` can set error regression's grasp and lift steps against the open loop's. One core.
while ! grep -q " table2_resets rc" /work/exp84b/logs/chain10.progress 2>/dev/null; do sleep 20; done
cd /work/exp84c
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84c MUJOCO_GL=egl OMP_NUM_THREADS=1
T=results/demonstrations/teleop_placed/trace
predvla trace $T/table2_open_loop_task6 --policy.path=/work/exp84c/checkpoints/demonstrations/teleop_placed/table2_seed0 \
  --policy.device=cpu --policy.er_iterations=0 --env.type=predvla_libero --env.task=libero_object \
  --env.episode_length=600 --env.init_states=true --eval.n_episodes=1 --eval.batch_size=1 \
  --eval.use_async_envs=false --seed=0 '--env.task_ids=[6]' > /work/exp84b/logs/trace_ol.log 2>&1
echo "$(date -u) ol trace rc=$?" >> /work/exp84b/logs/chain10.progress
python -m research.er_timing --trace $T/table2_task6 --open-loop $T/table2_open_loop_task6 --out $T/timing \
  > /work/exp84b/logs/er_timing.log 2>&1
echo "$(date -u) er_timing rc=$?" >> /work/exp84b/logs/chain10.progress
