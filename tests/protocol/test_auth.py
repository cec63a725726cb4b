"""The credential's challenge and response (protocol/auth.py): what a key file holds, and a
proof that is good for one key, one challenge and one nonce only."""

from __future__ import annotations

import re

import pytest

from protocol.auth import (KeyFileError, new_challenge, new_key_text, proof, read_key_text,
                           verify)


def test_a_new_key_reads_back_and_comments_are_allowed() -> None:
    text = new_key_text()
    key = read_key_text(text)
    assert len(key) == 32 and text == key.hex() + "\n"
    assert read_key_text(f"# the arm's key\n\n{key.hex().upper()}\n") == key


@pytest.mark.parametrize("text, got", [("", "0 line(s)"), ("abc\n", "1 line(s) of 3"),
                                       ("0" * 64 + "\n" + "1" * 64, "2 line(s)"),
                                       ("g" * 64, "1 line(s) of 64")])
def test_a_bad_key_file_says_what_it_expected(text: str, got: str) -> None:
    with pytest.raises(KeyFileError, match="keys/arm: expected one line of 64 hex digits.*"
                                           "got " + re.escape(got)):
        read_key_text(text, "keys/arm")


def test_a_proof_is_good_for_its_key_challenge_and_nonce_only() -> None:
    key, other = read_key_text(new_key_text()), read_key_text(new_key_text())
    challenge, nonce = new_challenge(), "ab" * 16
    given = proof(key, challenge, nonce)
    assert verify(key, challenge, nonce, given)
    assert verify(key, challenge, nonce, given.upper())
    assert not verify(other, challenge, nonce, given)
    assert not verify(key, new_challenge(), nonce, given)  # another connection's challenge
    assert not verify(key, challenge, "cd" * 16, given)
    assert not verify(key, challenge, "xyz", proof(key, challenge, "xyz"))  # not a nonce
    assert new_challenge() != challenge
