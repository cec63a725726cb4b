"""Coverage-guided fuzzing (atheris) of the OpenIGTLink decoder and the command schema.

Simplest:      make fuzz [FUZZ_SECONDS=600]   (installs the pinned `fuzz` extra, keeps
               its corpus and findings in .cache/fuzz)
By hand:       .venv/bin/pip install -e '.[fuzz]'   (atheris: a wheel for CPython 3.11 x86-64)
               .venv/bin/python bench/fuzz_decoder.py [-max_total_time=600] [CORPUS_DIR]
               .venv/bin/python bench/fuzz_decoder.py -runs=200000
               .venv/bin/python bench/fuzz_decoder.py --seed-only CORPUS_DIR  (write seeds)

Any libFuzzer flag works (-max_total_time, -runs, -jobs, -dict...). Without a corpus
directory a temporary one is made, seeded with one valid message of every type (header v1
and v2, with metadata) and valid commands of every op, so mutations start from real
structure rather than noise.

The contract checked, per input: the first byte picks a target, the rest is the input.
- decoder: bytes fed in 1..64-byte chunks (the chunking taken from the input too) yield
  messages, `MessageError` (skip and go on) or `FramingError` (close); with the CRC left
  unchecked as well, so mutations reach the body parsers. Anything else is a crash. Every
  decoded message must encode again (v1 and v2) without an unexpected exception.
- commands: NAME and text -> a request or a `CommandError`; an accepted request encodes
  to JSON that parses to the same request.
A finding is written as crash-<sha1> in the working directory; re-run with that file as
the only argument to reproduce.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from protocol import commands as c  # noqa: E402
from protocol.errors import EncodeError, FramingError, MessageError  # noqa: E402
from protocol.framing import Decoder, encode  # noqa: E402
from protocol.messages import (Command, Image, Message, Point, PointElement,  # noqa: E402
                               PolyData, RtsCommand, Status, String, Transform)

OPS = sorted(c.REQUEST_TYPES)
DECODER, DECODER_NO_CRC, COMMAND = 0, 1, 2


def seed_messages() -> list[Message]:
    pixels = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(1, 2, 3, 4)
    triangles = np.array([3, 0, 1, 2], dtype=np.uint32)
    return [
        Message(device_name="tool", body=Transform(matrix=np.eye(4))),
        Message(device_name="text", body=String(text="héllo")),
        Message(device_name="st", body=Status(code=5, error_name="x", text="denied")),
        Message(device_name="img", body=Image(pixels=pixels)),
        Message(device_name="mesh", body=PolyData(
            points=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32),
            polygons=triangles)),
        Message(device_name="pts", body=Point(points=[PointElement(name="a", group="g")])),
        Message(device_name="command", body=Command(command_id=3, name="hello",
                                                    text='{"client":"fuzz"}')),
        Message(device_name="command", body=RtsCommand(command_id=3, name="hello",
                                                       text='{"ok":true}')),
    ]


def seed_commands() -> list[tuple[str, dict]]:
    eye = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    return [("hello", {}), ("create_subscriber", {"topic": "/a", "type": "PoseStamped",
                                                  "qos": {"depth": 5}, "rate_hz": 30}),
            ("publish", {"topic": "/a", "value": {"x": [1, 2.5, "s", None, True]}}),
            ("set_parameters", {"node": "/n", "values": {"p": {"type": "double_array",
                                                               "value": [1.0, 2.0]}}}),
            ("broadcast_transform", {"parent": "a", "child": "b", "matrix": eye,
                                     "stamp": {"sec": 1, "nanosec": 2}}),
            ("call_service", {"service": "/s", "type": "std_srvs/srv/SetBool",
                              "request": {"data": True}, "timeout": 1.5}),
            ("create_robot", {"name": "r", "source": {"kind": "parameter", "node": "/rsp"}})]


def write_seeds(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for index, message in enumerate(seed_messages()):
        for version in (1, 2):
            message.metadata = {"k": "v"} if version == 2 else {}
            data = encode(message, header_version=version)
            for target in (DECODER, DECODER_NO_CRC):
                (folder / f"msg-{index}-v{version}-{target}").write_bytes(bytes([target, 7])
                                                                           + data)
    for op, args in seed_commands():
        payload = bytes([COMMAND, OPS.index(op)]) + json.dumps(args).encode()
        (folder / f"cmd-{op}").write_bytes(payload)


def decode_all(data: bytes, chunk: int, verify_crc: bool) -> None:
    decoder = Decoder(max_body_size=1 << 20, verify_crc=verify_crc)
    for start in range(0, len(data), chunk):
        decoder.feed(data[start:start + chunk])
        while True:
            try:
                message = decoder.next_message()
            except MessageError:
                continue
            if message is None:
                break
            for version in (1, 2):
                try:
                    encode(message, header_version=version)
                except EncodeError:
                    pass  # a decoded value the encoder refuses by name is fine


def test_one_input(data: bytes) -> None:
    if len(data) < 2:
        return
    target, knob, rest = data[0] % 3, data[1], data[2:]
    if target in (DECODER, DECODER_NO_CRC):
        try:
            decode_all(rest, 1 + knob % 64, verify_crc=target == DECODER)
        except FramingError:
            pass
        return
    op = OPS[knob % len(OPS)] if knob < 250 else "no_such_op"
    try:
        request = c.parse_request(op, rest)
    except c.CommandError:
        return
    again = c.parse_request(op, request.to_json())
    assert again == request, (request, again)


def main() -> None:
    if sys.argv[1:2] == ["--seed-only"]:
        write_seeds(Path(sys.argv[2]))
        return
    import atheris

    argv = list(sys.argv)
    folders = [Path(arg) for arg in argv[1:] if not arg.startswith("-")]
    if not folders:
        corpus = Path(tempfile.mkdtemp(prefix="fuzz-corpus-"))
        write_seeds(corpus)
        argv.append(str(corpus))
        print(f"corpus: {corpus}", flush=True)
    elif folders[0].is_dir() and not any(folders[0].iterdir()):
        write_seeds(folders[0])  # a new corpus folder starts from the seeds too
    atheris.instrument_all()
    atheris.Setup(argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
