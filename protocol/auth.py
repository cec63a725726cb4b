"""The credential a writer presents: a challenge and response over a shared key, as
rosbridge's `authenticate` op (rosauth) does, with HMAC-SHA256.

The operator makes a key once (`slicer-ros2-bridge keygen FILE`: 32 random bytes, hex) and
gives the daemon (``--key-file``) and each writer's machine the same file. On every
connection the daemon's `hello` reply carries a fresh random challenge; the client answers
`authenticate` with a nonce of its own and ``proof(key, challenge, nonce)``. The key never
travels, and a proof is good for that one connection only (the challenge is new each
time). Confidentiality is TLS's job (``--tls-cert``), not this module's.

Sans-I/O: no socket, no file; the key file is read by the caller (`read_key_text`).
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets

__all__ = ["KEY_BYTES", "NONCE", "KeyFileError", "new_challenge", "new_key_text", "proof",
           "read_key_text", "verify"]

KEY_BYTES = 32
_DOMAIN = b"slicer-ros2-bridge authenticate v1"
_HEX = re.compile(r"[0-9a-f]{64}\Z")
NONCE = re.compile(r"[0-9a-f]{32,128}\Z")


class KeyFileError(ValueError):
    """A key's text is not a key: says what was expected and what came."""


def new_key_text() -> str:
    """A new key as the file holds it: 64 hex digits and a newline."""
    return secrets.token_hex(KEY_BYTES) + "\n"


def read_key_text(text: str, where: str = "key") -> bytes:
    """The key in a key file's text (64 hex digits; blank lines and ``#`` comments
    allowed), or `KeyFileError` naming `where`."""
    lines = [line.strip() for line in text.splitlines()
             if line.strip() and not line.strip().startswith("#")]
    if len(lines) != 1 or not _HEX.match(lines[0].lower()):
        raise KeyFileError(f"{where}: expected one line of {2 * KEY_BYTES} hex digits (made by "
                        f"`slicer-ros2-bridge keygen FILE`), got "
                        f"{len(lines)} line(s)" + (f" of {len(lines[0])} characters"
                                                   if len(lines) == 1 else ""))
    return bytes.fromhex(lines[0])


def new_challenge() -> str:
    return secrets.token_hex(32)


def proof(key: bytes, challenge: str, nonce: str) -> str:
    """HMAC-SHA256 over the protocol's name, the daemon's challenge and the client's nonce."""
    message = b"\n".join((_DOMAIN, challenge.encode("ascii"), nonce.encode("ascii")))
    return hmac.new(key, message, hashlib.sha256).hexdigest()


def verify(key: bytes, challenge: str, nonce: str, given: str) -> bool:
    """Is `given` the proof of this key for this challenge and nonce (in constant time)?"""
    if not NONCE.match(nonce) or not isinstance(given, str):
        return False
    return hmac.compare_digest(proof(key, challenge, nonce), given.lower())
