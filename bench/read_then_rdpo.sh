#!/usr/bin/env bash
# Issue 28 item 3 from a student that reads the user's answer (docs/training.md, "A student that reads the
# answer on the whole prompt, and Reflection-DPO from it"), every step of the twelfth session in one resumable
# command: each step is skipped when its output is there, so a rerun after a kill goes on where it stopped.
#
#     bash bench/read_then_rdpo.sh [DIR]          # default runs/read-rdpo; ~3.5 h on 2 CPU cores
#     DRY=1 bash bench/read_then_rdpo.sh /tmp/dry  # the same commands at a few minutes' scale
#
# 1. rows:    the shipped student trained on split 0's answer rows alone, cut to their dialogue
#             (bench/answer_context.py: 1,500 updates x 8 rows, lr 1e-3): reads replies, cooks nothing.
# 2. oracle:  the oracle's episodes on split 0's twelve training personas, scene seeds 124-129 (576);
#             AGENT=oracle-ask: the oracle that asks at the recipes' choices instead (a base that asks).
# 3. read:    each update 4 of those episodes and 4 answer rows on the whole prompt (bench/cook_and_read.py,
#             200 updates, lr 5e-4): reads on the prompt it acts on, cooks a little.
# 4. base:    every weight 0.3 x the shipped student + 0.7 x step 3's model (bench/interpolate.py).
# 5. pairs:   Reflection-DPO's rows from the base (training personas, scene seed 100, --questions choices).
# 6. dpo:     60 updates, sigmoid+sft, lr 3e-4, LoRA rank 8 on every linear layer.
# 7. evals:   the base and the DPO model as the planner on split 0's unseen personas x 8 tasks x scene seeds
#             0-7 (256 episodes, 50 steps, greedy), then `adapt eval --paired base` (clustered by scene).
# 8. probe:   the base's answer-use probe (unseen personas, 200 pairs, float32: OUT/base-probe.json).
# The base's evaluation and probe may run beside steps 5-6 by hand (the same commands); their step skips or
# resumes them.
# ABLATIONS=1 adds no-DPO (`adapt train sft`) and no-reflection on the same pairs, evaluated the same way.
# READ_FROM=student starts step 3 from the shipped student instead of step 1's model (step 1 still runs: its
# rows are step 3's).
# ORACLE_SEEDS=130-169 gives step 3 the oracle's episodes on 40 scenes instead of 6 (the fifteenth session: on 6
# scenes the reader named objects the scene before it did not have, and cooked 2-4 times fewer dishes).
# QSET=bank decodes the student's questions from the domain's own (`--question-set bank`, docs/grammar.md) in
# steps 5 and 7 (the sixteenth session: the student's free questions were garbled and off the task).
# LAYOUT=generation lays the trainers' rows out as the student plays (`adapt train ... --layout generation`).
# CONTRAST_STEPS=400 inserts two steps before the base (the twentieth session, "A reader that cooks"): step 4's
# model (now base0) trained CONTRAST_STEPS more updates of the same episodes with the answer rows as pairs
# (`bench/cook_and_read.py --row-loss contrast`, 4 + 4 pairs an update), then every weight CONTRAST_T (0.7) x that
# model + the rest the shipped student's: the base of steps 5-8.
# Settings by environment: AGENT, ORACLE_SEEDS, CUT_STEPS, READ_FROM, READ_STEPS, T, QSET, DPO_STEPS, LAYOUT,
# EVAL_SEEDS, WORKERS, THREADS, CONTRAST_STEPS, CONTRAST_T.
# The fourteenth session's runs (docs/training.md, "Bases that ask on their own"):
#     AGENT=oracle-ask T=0.9 ABLATIONS=1 bash bench/read_then_rdpo.sh runs/ask-rdpo
#     AGENT=oracle-ask READ_FROM=student READ_STEPS=100 T=1.0 ABLATIONS=1 bash bench/read_then_rdpo.sh runs/cookask-rdpo
# The fifteenth session's ("A reader trained on forty scenes"; its steps 1-3 were run by hand on 2,370 of these
# episodes, 8 personas):
#     AGENT=oracle-ask CUT_STEPS=1000 ORACLE_SEEDS=130-169 READ_STEPS=300 T=0.9 ABLATIONS=1 bash bench/read_then_rdpo.sh runs/many-rdpo
# The sixteenth session's ("Questions chosen from the domain's own"; steps 1-4 linked in from runs/many-rdpo):
#     AGENT=oracle-ask CUT_STEPS=1000 ORACLE_SEEDS=130-169 READ_STEPS=300 T=0.9 QSET=bank ABLATIONS=1 bash bench/read_then_rdpo.sh runs/bank-rdpo
# The twentieth session's (steps 1-4 linked in from runs/many-rdpo, base0 = runs/bank-rdpo/base):
#     AGENT=oracle-ask CUT_STEPS=1000 ORACLE_SEEDS=130-169 READ_STEPS=300 T=0.9 QSET=bank CONTRAST_STEPS=400 \
#         CONTRAST_T=0.7 ABLATIONS=1 bash bench/read_then_rdpo.sh runs/contrast-rdpo
set -u
dir=${1:-runs/read-rdpo}
mkdir -p "$dir/evals"
adapt() { python3 -m adaptbench.cli "$@"; }
train=juan,sarah,ramesh,jamal,ron,nalini,maya,miranda,maria,ethan,rachel,carlos   # split 0's training personas
unseen=leila,lisa,mark,samantha
if [ -n "${DRY:-}" ]; then
  cut=(--steps 2 --eval-every 2 --pairs 2 --full-pairs 1); read_steps=${READ_STEPS:-2}; read=(--eval-every 2 --pairs 2)
  oracle=(--personas juan --tasks eggs --seeds 124); pairs=(--personas juan --tasks eggs)
  evals=(--personas leila --tasks eggs --seeds 0 --max-steps 8); dpo_steps=${DPO_STEPS:-2}; probe=(--tasks eggs)
else
  cut=(--steps "${CUT_STEPS:-1500}" --eval-every 750); read_steps=${READ_STEPS:-200}; read=(--eval-every 100 --pairs 60)
  oracle=(--personas "$train" --tasks all --seeds "${ORACLE_SEEDS:-124-129}"); pairs=(--personas "$train" --tasks all)
  evals=(--personas "$unseen" --tasks all --seeds "${EVAL_SEEDS:-0-7}" --max-steps 50); dpo_steps=${DPO_STEPS:-60}; probe=()
fi
qset=${QSET:-free}   # bank: the student's Ask names one of the domain's questions, in the pairs and the evaluations
step() { echo "== $1 ($(date -u +%H:%M:%S))"; }
run() { "$@" || { echo "failed: $*" >&2; exit 1; }; }

step rows
[ -d "$dir/rows/model" ] || run python3 bench/answer_context.py --out "$dir/rows" "${cut[@]}"
agent=${AGENT:-oracle}
step "$agent"   # adapt rollout resumes a partly written file; only step 3 reads it
[ -d "$dir/read/model-$read_steps" ] || run adapt rollout --agent "$agent" "${oracle[@]}" --quiet --out "$dir/$agent.jsonl"
step read
[ -d "$dir/read/model-$read_steps" ] || { rm -rf "$dir/read"; run python3 bench/cook_and_read.py --out "$dir/read" \
  --model "${READ_FROM:-$dir/rows/model}" --episodes "$dir/$agent.jsonl" --rows "$dir/rows/rows.jsonl" --steps "$read_steps" \
  --lr 5e-4 --threads "${THREADS:-1}" "${read[@]}"; }
if [ -n "${CONTRAST_STEPS:-}" ]; then   # the twentieth session: the reader's reading sharpened, then its cooking restored
  contrast_steps=$([ -n "${DRY:-}" ] && echo 2 || echo "$CONTRAST_STEPS")
  step base0
  [ -d "$dir/base0" ] || run python3 bench/interpolate.py --a student --b "$dir/read/model-$read_steps" --t "${T:-0.7}" --out "$dir/base0"
  step contrast
  [ -d "$dir/contrast/model-$contrast_steps" ] || { rm -rf "$dir/contrast"; run python3 bench/cook_and_read.py \
    --out "$dir/contrast" --model "$dir/base0" --episodes "$dir/$agent.jsonl" --rows "$dir/rows/rows.jsonl" \
    --steps "$contrast_steps" --row-loss contrast --rows-per-update 8 --lr 5e-4 --threads "${THREADS:-1}" "${read[@]}"; }
  step base
  [ -d "$dir/base" ] || run python3 bench/interpolate.py --a student --b "$dir/contrast/model-$contrast_steps" \
    --t "${CONTRAST_T:-0.7}" --out "$dir/base"
else
  step base
  [ -d "$dir/base" ] || run python3 bench/interpolate.py --a student --b "$dir/read/model-$read_steps" --t "${T:-0.7}" --out "$dir/base"
fi
step pairs
run adapt train data --student "$dir/base" --split 0 --seeds 100 "${pairs[@]}" --max-steps 50 --batch 16 \
  --questions choices --question-set "$qset" --workers "${WORKERS:-2}" --out "$dir/pairs"
lora=(--lr 3e-4 --lora-targets all-linear --lora-r 8 --lora-alpha 16 --max-steps "$dpo_steps" --threads "${THREADS:-2}"
      --layout "${LAYOUT:-chat}")
step dpo
[ -d "$dir/dpo/merged" ] || run adapt train dpo --data "$dir/pairs" --model "$dir/base" --out "$dir/dpo" --loss sigmoid+sft "${lora[@]}"
methods=(base=base reflection-dpo=dpo/merged)
if [ -n "${ABLATIONS:-}" ]; then
  step ablations
  [ -d "$dir/sft/merged" ] || run adapt train sft --data "$dir/pairs" --model "$dir/base" --out "$dir/sft" "${lora[@]}"
  [ -d "$dir/norefl/merged" ] || run adapt train no-reflection --data "$dir/pairs" --model "$dir/base" --out "$dir/norefl" \
    --loss sigmoid+sft "${lora[@]}"
  methods+=(no-dpo=sft/merged no-reflection=norefl/merged)
fi
spec=()
for m in "${methods[@]}"; do
  step "eval ${m%%=*}"   # resumes a partly written file
  run adapt rollout --agent planner --model "$dir/${m#*=}" "${evals[@]}" --question-set "$qset" --batch 16 --quiet \
    --out "$dir/evals/${m%%=*}.jsonl"
  spec+=(--method "${m%%=*}@0=$dir/evals/${m%%=*}.jsonl")
done
step table
adapt eval "${spec[@]}" --paired base | tee "$dir/table.txt"
step probe
[ -s "$dir/base-probe.json" ] || run adapt probe answers --model "$dir/base" --personas "$unseen" "${probe[@]}" \
  --dtype float32 --quiet --json > "$dir/base-probe.json"
