"""Issue 43, item 5, through the real daemon: a peer's /tf flood that fills the tf buffer
(one message of 9,999 frames) must not keep a frame published after it out, whatever the
flood's stamps: far in the future (sec = 2**31-1, which never went stale when staleness was
judged by the newest stamp) or now (kept out for a cache time).

The peer (tests/peers/tf_flood_publisher.py) sends the new frame twice only, 50 ms apart:
if a client's lookup finds it, it got in from its first message or two. The lookup waits on
the daemon's tf events with a bounded timeout.
"""

from __future__ import annotations

import itertools

import pytest

from slicer_client.connection import CommandRefusedError, Connection
from support import Processes, scaled, start_daemon

FUTURE_SEC = 2**31 - 1
_prefixes = itertools.count()


@pytest.mark.parametrize("pure_python", [False, True], ids=["compiled store", "Python store"])
@pytest.mark.parametrize("flood_sec", [FUTURE_SEC, None], ids=["future", "now"])
def test_a_flood_filling_the_buffer_cannot_keep_a_new_frame_out(
        processes: Processes, flood_sec: int | None, pure_python: bool) -> None:
    from bridge.tf.buffer import CompiledFrameStore

    if not pure_python and CompiledFrameStore is None:
        pytest.skip("the compiled tf store was not built (no C compiler or Cython at install)")
    daemon = start_daemon(processes, "--tf-store", "python" if pure_python else "compiled")
    p = f"flood{next(_prefixes)}_"
    stamp = [] if flood_sec is None else ["--sec", str(flood_sec)]
    peer = processes.python("flood", "tf_flood_publisher.py", p, *stamp)
    peer.wait_for_output("FLOOD SENT", timeout=60)
    peer.wait_for_output("NEW DONE", timeout=20)
    with Connection("127.0.0.1", daemon.port) as client:
        wait = min(scaled(20), 60.0)  # the most lookup_transform waits
        new = client.command("lookup_transform", {"parent": p + "world", "child": p + "new",
                                                  "timeout": wait}, timeout=wait + 10)
        assert new["translation"] == [1.0, 0.0, 0.0]
        # The flood was there first and filled the buffer: the daemon made room by
        # forgetting a tenth of the bound, the frames received least recently (the flood's,
        # ties in name order), and said so once.
        daemon.child.wait_for_output(
            "the tf buffer was full (10000 frames): forgot 1000 frame(s), those received "
            "least recently, to make room for new ones", timeout=10)
        kept = client.command("lookup_transform", {"parent": p + "world",
                                                   "child": p + "junk9998"})
        assert kept["translation"] == [0.0, 0.0, 1.0]
        if flood_sec is not None:
            assert kept["stamp"]["sec"] == flood_sec
        with pytest.raises(CommandRefusedError, match="does not exist"):
            client.command("lookup_transform", {"parent": p + "world",
                                                "child": p + "junk0000"})
