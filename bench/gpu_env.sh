# Sourced by the device scripts (gpu_run.sh, gpu_student.sh): on a machine without the project installed, the
# wheels of what it lacks in .whl/ (shared/notes/gpu.md lists them) go to /tmp/site, and the project's src/
# and they go on PYTHONPATH, so `python3 -m adaptbench.cli` runs without an install.
if [ -d .whl ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || exit 1
  export PYTHONPATH=/tmp/site:${PYTHONPATH:-}
fi
export PYTHONPATH=$PWD/src:${PYTHONPATH:-} PYTHONUNBUFFERED=1
