"""Idle TCP connections, as a host outside ``--allow`` (or a slow one) holds them: connected,
and never a byte sent (on a TLS port, a ClientHello that never comes).

usage: idle_connections.py HOST PORT COUNT --hold SECONDS
Opens COUNT connections, prints `OPEN <connected> <failed>`, then watches them until each is
closed by the daemon or SECONDS have passed, and prints
`SUMMARY opened=N closed=M held=K last_close_s=T` (T: seconds from the end of the opening
to the last close seen; -1 if none). Exits 0.
"""

import argparse
import resource
import selectors
import socket
import time


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("host")
    parser.add_argument("port", type=int)
    parser.add_argument("count", type=int)
    parser.add_argument("--hold", type=float, required=True)
    args = parser.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = args.count + 64
    if soft < want:  # this peer holds more than the usual 1024 itself
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, max(hard, want)))
    selector = selectors.DefaultSelector()
    failed = 0
    for _ in range(args.count):
        try:
            sock = socket.create_connection((args.host, args.port), timeout=5)
        except OSError:
            failed += 1
            continue
        sock.setblocking(False)
        selector.register(sock, selectors.EVENT_READ)
    opened = len(selector.get_map())
    print(f"OPEN {opened} {failed}", flush=True)
    began = time.monotonic()
    deadline = began + args.hold
    closed, last_close = 0, -1.0
    while selector.get_map() and time.monotonic() < deadline:
        for key, _ in selector.select(timeout=max(0.0, deadline - time.monotonic())):
            sock = key.fileobj
            assert isinstance(sock, socket.socket)
            try:
                data = sock.recv(65536)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data:  # closed by the daemon (what it said first, if anything, is read)
                selector.unregister(sock)
                sock.close()
                closed += 1
                last_close = time.monotonic() - began
    held = len(selector.get_map())
    print(f"SUMMARY opened={opened} closed={closed} held={held} "
          f"last_close_s={last_close:.2f}", flush=True)
    for key in list(selector.get_map().values()):
        key.fileobj.close()  # type: ignore[union-attr]
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
