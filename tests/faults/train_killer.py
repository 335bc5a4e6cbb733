"""Run `adapt ARGS` and SIGKILL the process at a named moment of a training run (a fault injected at a
known point, so that every moment the tests name is hit, not only the ones a timer happens to catch).

    python tests/faults/train_killer.py MOMENT train dpo --data ... --out ...

MOMENT: `log:N` (step N's log line written, its checkpoint not yet), `adapter` (the adapter written beside
OUT/adapter, not put in place), `merged` (the merged model written beside OUT/merged, not put in place),
`result` (train.json's temporary file written, not put in place), or `none`.
"""

from __future__ import annotations

import os
import signal
import sys


def _die() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _arm(moment: str) -> None:
    from adaptbench.training.trainers import engine, run

    if moment.startswith("log:"):
        step, progress = int(moment[4:]), engine.progress_callback

        def callback(out, log):
            cb = progress(out, log)
            on_log = cb.on_log

            def logged(args, state, control, logs=None, **kw):
                on_log(args, state, control, logs=logs, **kw)
                if state.global_step == step:
                    _die()
            cb.on_log = logged
            return cb
        engine.progress_callback = callback
    elif moment == "adapter":
        save = engine.save_adapter
        engine.save_adapter = lambda trainer, out: (save(trainer, out), _die())
    elif moment == "merged":
        replace = engine.replace_dir
        engine.replace_dir = lambda tmp, final: _die() if final.name == "merged" else replace(tmp, final)
    elif moment == "result":
        def write(out, result):
            (out / "train.json.tmp").write_text("{\"steps\": ")
            _die()
        run.write_result = write


if __name__ == "__main__":
    _arm(sys.argv[1])
    from adaptbench.cli.main import main

    sys.exit(main(sys.argv[2:]))
