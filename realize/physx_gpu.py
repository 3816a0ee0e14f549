"""SAPIEN's PhysX GPU library: where SAPIEN looks for it, whether it is there and whole, fetching it.

SAPIEN 3.0 loads PhysX's GPU solver from ``~/.sapien/physx/<physx version>/libPhysXGpu_64.so``
and, the first time GPU physics is enabled without it, downloads a zip of it from GitHub with
no timeout (``sapien.physx.enable_gpu``): offline that hangs or ends in a bare ConnectionError,
and a download stopped while the zip is unpacked leaves a partial file that SAPIEN takes from
then on. What this module does:

  * ``library_location()``: the file and the URL SAPIEN uses on this machine;
  * ``library_problem(path)``: ``None`` for a whole ELF library, else one line (missing, not an
    ELF file, or shorter than its own ELF header says: SAPIEN records no size or hash, so the
    header's section and segment tables are the check);
  * ``check_library()``: ``ConfigError`` with that line, the file and the URL; called where
    ``sim.backend = gpu`` is chosen (``realize.scene.backends``), before anything is built;
  * ``fetch_library()``: the download SAPIEN would do, with a time limit, unpacked next to the
    target and moved into place only when whole (``python -m realize.physx_gpu --fetch``;
    ``scripts/setup.sh`` runs it where there is an NVIDIA GPU).

What it doesn't: load the library or turn GPU physics on (SAPIEN does, when ManiSkill builds a
``physx_cuda`` env), or know other platforms than Linux (elsewhere the check is left to SAPIEN).
"""

from __future__ import annotations

import argparse
import os
import platform
import struct
import sys
import tempfile
import time
import urllib.request
import zipfile
from pathlib import Path

from realize.config import ConfigError

__all__ = ["LIBRARY", "library_location", "library_problem", "check_library", "fetch_library"]

LIBRARY = "libPhysXGpu_64.so"
_RELEASES = "https://github.com/sapien-sim/physx-precompiled/releases/download"
_ZIPS = {"x86_64": "linux-so.zip", "AMD64": "linux-so.zip", "aarch64": "linux-aarch64-so.zip",
         "arm64": "linux-aarch64-so.zip"}
_PT_LOAD = 1


def physx_version() -> str:
    """The PhysX version SAPIEN was built with (it names SAPIEN's folder and release)."""
    import sapien.physx

    return str(sapien.physx.version())


def library_location(version: str | None = None) -> tuple[Path, str] | None:
    """``(file, url)``: where SAPIEN looks for the PhysX GPU library on this machine and where it
    downloads it from, as ``sapien.physx.enable_gpu`` does; None off Linux (not checked here)."""
    zip_name = _ZIPS.get(platform.machine())
    if platform.system() != "Linux" or zip_name is None:
        return None
    version = version or physx_version()
    return Path.home() / ".sapien" / "physx" / version / LIBRARY, f"{_RELEASES}/{version}/{zip_name}"


def _elf_end(head: bytes) -> int:
    """The least file size the ELF header in ``head`` (the file's first bytes) asks for: the end of
    the section header table and of every loadable segment whose program header ``head`` holds."""
    wide = head[4] == 2
    order = "<" if head[5] == 1 else ">"
    if wide:
        phoff, shoff = struct.unpack_from(order + "QQ", head, 0x20)
        phentsize, phnum, shentsize, shnum = struct.unpack_from(order + "HHHH", head, 0x36)
    else:
        phoff, shoff = struct.unpack_from(order + "II", head, 0x1C)
        phentsize, phnum, shentsize, shnum = struct.unpack_from(order + "HHHH", head, 0x2A)
    end = max(shoff + shentsize * shnum if shoff else 0, phoff + phentsize * phnum)
    for i in range(phnum):
        at = phoff + i * phentsize
        if at + phentsize > len(head):
            break
        if wide:
            p_type, _, p_offset, _, _, p_filesz = struct.unpack_from(order + "IIQQQQ", head, at)
        else:
            p_type, p_offset, _, _, p_filesz = struct.unpack_from(order + "IIIII", head, at)
        if p_type == _PT_LOAD:
            end = max(end, p_offset + p_filesz)
    return end


def library_problem(path: Path) -> str | None:
    """None where ``path`` is a whole ELF file, else what is wrong with it, in a few words."""
    if not path.is_file():
        return "is missing"
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(1 << 16)  # the ELF header and the program headers after it
    if len(head) < 64 or head[:4] != b"\x7fELF" or head[4] not in (1, 2) or head[5] not in (1, 2):
        return f"is not an ELF library ({size} bytes)"
    need = _elf_end(head)
    if size < need:
        return f"is truncated ({size} bytes; its ELF header says at least {need}: a download stopped halfway)"
    return None


def check_library(where: str = "sim.backend") -> None:
    """Refuse GPU physics in one line where SAPIEN's PhysX GPU library is missing or partial."""
    loc = library_location()
    if loc is None:
        return
    path, url = loc
    problem = library_problem(path)
    if problem is not None:
        raise ConfigError(
            f"{where} = 'gpu' needs SAPIEN's PhysX GPU library {path}, which {problem}; SAPIEN gets it from "
            f"{url} (a download without a time limit): run `python -m realize.physx_gpu --fetch` (or "
            f"scripts/setup.sh) where there is network, or unzip that file into {path.parent}"
        )


def fetch_library(timeout_s: float = 300.0, url: str | None = None, dest: Path | None = None) -> Path:
    """Download and unpack the PhysX GPU library where SAPIEN looks for it (or ``dest``), within
    ``timeout_s``; the file appears only once it is whole. Raises ``ConfigError`` (one line)."""
    loc = library_location() if url is None or dest is None else None
    if loc is None and (url is None or dest is None):
        raise ConfigError(f"the PhysX GPU library is fetched on Linux only (this is {platform.system()} "
                          f"{platform.machine()})")
    dest = dest or loc[0]  # type: ignore[index]
    url = url or loc[1]  # type: ignore[index]
    dest.parent.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + timeout_s
    with tempfile.TemporaryDirectory(dir=dest.parent, prefix=".fetch-") as tmp:
        archive = Path(tmp) / "physx.zip"
        try:
            with urllib.request.urlopen(url, timeout=min(timeout_s, 30.0)) as r, open(archive, "wb") as f:
                while chunk := r.read(1 << 20):
                    f.write(chunk)
                    if time.monotonic() > deadline:
                        raise TimeoutError(f"not done after {timeout_s:.0f} s")
            with zipfile.ZipFile(archive) as z:
                member = next((n for n in z.namelist() if Path(n).name == LIBRARY), None)
                if member is None:
                    raise ConfigError(f"{url} holds no {LIBRARY}")
                z.extract(member, tmp)
        except (OSError, zipfile.BadZipFile) as e:  # URLError, timeouts and HTTP errors are OSErrors
            raise ConfigError(f"could not fetch the PhysX GPU library from {url}: "
                              f"{' '.join(str(e).split()) or type(e).__name__}") from None
        got = Path(tmp) / member
        problem = library_problem(got)
        if problem is not None:
            raise ConfigError(f"the {LIBRARY} in {url} {problem}")
        os.replace(got, dest)
    return dest


def main(argv: list[str] | None = None) -> int:
    """``python -m realize.physx_gpu [--fetch] [--timeout S]``: say whether the library is
    there and whole (exit 0) or not (exit 1); ``--fetch`` downloads it where it is not."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fetch", action="store_true", help="download it where it is missing or partial")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds the download may take")
    args = ap.parse_args(argv)
    loc = library_location()
    if loc is None:
        print(f"physx_gpu: not checked on {platform.system()} {platform.machine()} (SAPIEN handles it)")
        return 0
    path, url = loc
    problem = library_problem(path)
    if problem is not None and args.fetch:
        print(f"physx_gpu: {path} {problem}; fetching {url} (at most {args.timeout:.0f} s)", flush=True)
        try:
            fetch_library(args.timeout)
        except ConfigError as e:
            print(f"physx_gpu: error: {e}", file=sys.stderr)
            return 1
        problem = library_problem(path)
    print(f"physx_gpu: {path} {problem or 'is there and whole'}")
    return 0 if problem is None else 1


if __name__ == "__main__":
    sys.exit(main())
