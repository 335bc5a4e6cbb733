#!/usr/bin/env bash
# Issue 28 on a GPU in one run (docs/training.md, "A larger student on a GPU: prepared, not yet run"): a base
# student larger than the CPU's (default 256 x 6, ~5 M parameters) behaviour-cloned on the oracle's episodes of
# split 0's training personas with answer-following rows beside them, then its answer-use probe (unseen
# personas, seed 0) and its planner evaluation (split 0's unseen personas x 8 tasks x seeds 0-3, 50 steps,
# greedy). The trained model comes back in OUT/student (model and tokenizer files, student.json), small enough
# to carry back, so that a CPU session runs Reflection-DPO from it (`adapt train reproduce --base OUT/student`).
#
#     PREP=1 bash bench/gpu_student.sh           # first, here on the CPU: the teacher data, gzipped, in gpu-data/
#                                                # (~20 min on 2 cores; the device has no time to spare for it)
#     bash bench/gpu_student.sh [OUT_DIR]        # on the device, carry [".whl", "gpu-data"]; OUT default: $OUT
#     DRY=1 bash bench/gpu_student.sh /tmp/dry   # the same commands at a few seconds' scale, on the CPU
#
# Settings by environment: HIDDEN, LAYERS, STEPS, LR, ORACLE (scene seeds), PAIRS (answer-row scene seeds),
# WORDS (the tokenizer's word split, joined or spaced: `adapt model student --words`), ACCUMULATE (sequences an
# update, default 1) and ROWS_CONTEXT (full or dialogue: what of an answer row's prompt is trained on), WORKERS,
# LIMIT (seconds for the training command; a killed run resumes from its last checkpoint).
set -u
out=${1:-${OUT:-gpu-student}}
mkdir -p "$out"
. bench/gpu_env.sh
if [ -n "${DRY:-}" ]; then
  dev=cpu; hidden=${HIDDEN:-32}; layers=${LAYERS:-1}; steps=${STEPS:-4}; oracle=${ORACLE:-100}; pairs=${PAIRS:-100}
  tasks="--tasks eggs"; personas=leila; seeds=0; batch=4; workers=${WORKERS:-1}
else
  dev=cuda; hidden=${HIDDEN:-256}; layers=${LAYERS:-6}; steps=${STEPS:-4000}; oracle=${ORACLE:-100-123}
  pairs=${PAIRS:-100-101}; tasks=""; personas=leila,lisa,mark,samantha; seeds=0-3; batch=64; workers=${WORKERS:-12}
fi
adapt() { python3 -m adaptbench.cli "$@"; }
settings=(--split 0 --ask-seeds none --oracle-seeds "$oracle" --pair-seeds "$pairs" $tasks)
if [ -n "${PREP:-}" ]; then   # the teacher data only, here: OUT/data gzipped into gpu-data/ for the carry
  adapt model student --out gpu-data/build "${settings[@]}" --workers 2 --data-only || exit 1
  gzip -kf gpu-data/build/data/*.jsonl && mkdir -p gpu-data/data && mv gpu-data/build/data/*.jsonl.gz gpu-data/data/
  du -sh gpu-data/data; exit 0
fi
if [ -d gpu-data/data ]; then   # the data built here before (PREP=1): the student command keeps it
  mkdir -p "$out/build/data" && for f in gpu-data/data/*.jsonl.gz; do gunzip -c "$f" > "$out/build/data/$(basename "$f" .gz)"; done
fi
{ nvidia-smi --query-gpu=name,memory.total --format=csv,noheader 2>/dev/null || echo "no GPU"; nproc; } | tee "$out/machine.txt"
start=$(date +%s)
timeout "${LIMIT:-480}" python3 -m adaptbench.cli model student --out "$out/build" "${settings[@]}" --hidden "$hidden" \
  --layers "$layers" --words "${WORDS:-joined}" --accumulate "${ACCUMULATE:-1}" --rows-context "${ROWS_CONTEXT:-full}" --steps "$steps" --lr "${LR:-1e-3}" --device "$dev" --workers "$workers" --save-every 500 \
  --quiet 2>&1 | tail -5 | tee "$out/train.txt"
echo "student: $(( $(date +%s) - start )) s (whole process)" | tee -a "$out/train.txt"
mkdir -p "$out/student"
cp "$out"/build/*.json "$out"/build/*.safetensors "$out"/build/*.jinja "$out/student/" 2>/dev/null
ls "$out/student" | tee -a "$out/train.txt"
start=$(date +%s)
adapt probe answers --model "$out/student" --device "$dev" $tasks --quiet --json > "$out/probe.json" 2> "$out/probe.err"
echo "probe: $(( $(date +%s) - start )) s" | tee -a "$out/train.txt"
start=$(date +%s)
adapt rollout --agent planner --model "$out/student" --device "$dev" $tasks --personas "$personas" --seeds "$seeds" \
  --max-steps 50 --batch "$batch" --quiet --out "$out/eval.jsonl" 2>&1 | tail -3
adapt eval "$out/eval.jsonl" > "$out/eval.txt" 2>&1
echo "evaluation: $(( $(date +%s) - start )) s" | tee -a "$out/train.txt"
cat "$out/eval.txt"
rm -rf "$out/build"   # data, checkpoints and the untrained model: OUT/student has the model and its student.json
