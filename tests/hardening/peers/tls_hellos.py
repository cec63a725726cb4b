"""A client of the TLS port asking `hello` over a fresh connection each time, as a client
that reconnects would.

usage: tls_hellos.py HOST PORT CA_FILE COUNT
Prints `HELLO ok <ms>` or `HELLO fail <why>` for each of COUNT connections (connect,
handshake, hello, close), then `DONE <ok> <failed>`. Exits 0.
"""

import sys
import time

from slicer_client.connection import Connection
from slicer_client.client import tls_context


def main() -> int:
    host, port, ca_file, count = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
    context = tls_context(ca_file)
    ok = 0
    for _ in range(count):
        began = time.monotonic()
        try:
            with Connection(host, port, tls=context, connect_timeout=5) as client:
                assert client.command("hello", timeout=5)["ops"]
            ok += 1
            print(f"HELLO ok {(time.monotonic() - began) * 1000:.1f}", flush=True)
        except Exception as error:  # noqa: BLE001 - each failure is printed, not raised
            print(f"HELLO fail {type(error).__name__}: {error}", flush=True)
    print(f"DONE {ok} {count - ok}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
