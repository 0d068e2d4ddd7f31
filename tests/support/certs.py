"""Test certificates made with the ``openssl`` CLI (the venv has no ``cryptography``): a CA and
leaf certificates for 127.0.0.1/localhost with a given common name. Keys go to the caller's
tmp_path only, never into the repository."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

EC = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
LEAF_EXT = (
    "subjectAltName=IP:127.0.0.1,DNS:localhost\n"
    "basicConstraints=CA:FALSE\n"
    "keyUsage=digitalSignature\n"
    "extendedKeyUsage=serverAuth,clientAuth\n"
)


def openssl_missing() -> str | None:
    """Why certificates cannot be made here (None when they can)."""
    return None if shutil.which("openssl") else "the openssl CLI is not installed"


def _run(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def make_certs(folder: Path, names: list[str]) -> dict[str, tuple[Path, Path]]:
    """``ca.pem`` plus, for each name, ``(name.pem, name.key)`` signed by it (common name =
    name). Returns {"ca": (ca.pem, ca.key), name: (cert, key), ...}."""
    folder.mkdir(parents=True, exist_ok=True)
    _run("req", "-x509", *EC, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
         "-subj", "/CN=fleet-test-ca",
         "-addext", "basicConstraints=critical,CA:TRUE",
         "-addext", "keyUsage=critical,keyCertSign,cRLSign", cwd=folder)  # fmt: skip
    (folder / "leaf.ext").write_text(LEAF_EXT)
    out = {"ca": (folder / "ca.pem", folder / "ca.key")}
    for n in names:
        _run("req", *EC, "-keyout", f"{n}.key", "-out", f"{n}.csr", "-subj", f"/CN={n}",
             cwd=folder)  # fmt: skip
        _run("x509", "-req", "-in", f"{n}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
             "-CAcreateserial", "-out", f"{n}.pem", "-days", "2", "-extfile", "leaf.ext",
             cwd=folder)  # fmt: skip
        out[n] = (folder / f"{n}.pem", folder / f"{n}.key")
    return out
