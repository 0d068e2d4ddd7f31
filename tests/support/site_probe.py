"""A bare zenoh client for the multi-fleet site test, run inside a network namespace
(``python -m tests.support.site_probe ...``); every sample it receives is a JSON line in OUT.

- ``watch ENDPOINT OUT USER PASSWORD_FILE KEYEXPR...``: as ``USER``, subscribe to each key
  expression until SIGTERM; a line per sample: ``{"t": receive time (s), "key": ...,
  "payload": text}`` (flushed each line).
- ``intrude ENDPOINT OUT USER PASSWORD_FILE SECONDS PUT_KEY... -- SUB_KEYEXPR...``: as ``USER``
  (a robot's identity), subscribe to the ``SUB_KEYEXPR``\\ s, put ``"probe <key>"`` on each
  ``PUT_KEY`` every 0.1 s for SECONDS, then exit; its received samples are lines in OUT, then
  a last line ``{"done": true}``. A session receives its own puts on its own subscribers
  (zenoh delivers them locally, no router involved): they are lines too, with their payload.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time

import zenoh


def _session(endpoint: str, user: str = "", password_file: str = "") -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("client"))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if user:
        with open(password_file, encoding="utf-8") as f:
            password = f.read().strip()
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return zenoh.open(conf)


def _writer(path: str):
    out = open(path, "w", encoding="utf-8")  # noqa: SIM115 - closed at exit
    lock = threading.Lock()

    def write(obj: dict) -> None:
        with lock:
            out.write(json.dumps(obj) + "\n")
            out.flush()

    def on_sample(sample: zenoh.Sample) -> None:
        write(
            {
                "t": time.time(),
                "key": str(sample.key_expr),
                "payload": sample.payload.to_bytes().decode("utf-8", "replace"),
            }
        )

    return write, on_sample


def main(argv: list[str]) -> int:
    mode, endpoint, path = argv[:3]
    write, on_sample = _writer(path)
    if mode == "watch":
        stop = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        signal.signal(signal.SIGINT, lambda *_: stop.set())
        with _session(endpoint, argv[3], argv[4]) as s:
            subs = [s.declare_subscriber(k, on_sample) for k in argv[5:]]
            write({"ready": True, "t": time.time()})
            stop.wait()
            for sub in subs:
                sub.undeclare()
        return 0
    user, password_file, seconds = argv[3], argv[4], float(argv[5])
    rest = argv[6:]
    cut = rest.index("--")
    puts, subs = rest[:cut], rest[cut + 1 :]
    with _session(endpoint, user, password_file) as s:
        handles = [s.declare_subscriber(k, on_sample) for k in subs]
        write({"ready": True, "t": time.time()})
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for k in puts:
                s.put(k, f"probe {k}")
            time.sleep(0.1)  # the probe's own rate, not a wait for anything
        for h in handles:
            h.undeclare()
    write({"done": True, "t": time.time()})
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
