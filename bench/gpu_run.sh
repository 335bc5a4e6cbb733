#!/usr/bin/env bash
# The language-model side's GPU figures in one run (docs/llm.md, "On a GPU"): the GPU passes' tests on
# CUDA, then bench_llm.py with SmolLM2-135M's shape (random weights, bf16) comparing the model's forward
# (hf), the lean batched pass (lean), the lean pass with CUDA graphs in one lane (graphs:1) and in two
# half-batches that overlap the CPU's grammar work with the GPU's passes (graphs, llm/lanes.py), with an operator
# profile of the graphs pass at batch 64.
#
#     bash bench/gpu_run.sh [OUT_DIR]     # default: $OUT, else gpu-out/
#
# On a machine without the project installed, wheels of what it lacks in .whl/ are installed to
# /tmp/site first (shared/notes/gpu.md lists them); STEPS sets each episode's steps (default 8).
set -u
out=${1:-${OUT:-gpu-out}}
mkdir -p "$out"
. bench/gpu_env.sh
export TOKENIZERS_PARALLELISM=true
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
  python3 -c "import importlib.metadata as m; print(*(f'{p} {m.version(p)}' for p in ('torch', 'transformers', 'llguidance')))"
  nproc; } 2>&1 | tee "$out/machine.txt"
start=$(date +%s)
ADAPT_TEST_DEVICE=cuda timeout 150 python3 -m pytest -q -p no:cacheprovider tests/llm/test_batch_pass.py 2>&1 \
  | tail -4 | tee "$out/tests.txt"
echo "tests: $(( $(date +%s) - start )) s" | tee -a "$out/tests.txt"
start=$(date +%s)
timeout "${BENCH_LIMIT:-420}" python3 bench/bench_llm.py --shape smollm2 --model /tmp/smol --device cuda --dtype bfloat16 \
  --quick --passes hf,lean,graphs:1,graphs --steps "${STEPS:-8}" --profile "$out/profile.txt" 2>&1 \
  | grep -v "Loading weights\|Writing model" | tee "$out/bench.txt"
echo "bench: $(( $(date +%s) - start )) s (whole process)" | tee -a "$out/bench.txt"
