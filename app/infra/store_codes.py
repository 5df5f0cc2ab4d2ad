"""Codes of saved experiments and assignments, and the store's two kinds of failure.

A code reads like ``KN-7Q3M-X9TA-HPRW``: two letters from the exercise name, then twelve
random characters without look-alikes such as 0/O and 1/I, about 59 bits, so that guessing
codes is hopeless.  Codes of the older form, four random characters (``KN-7Q3M``), keep
opening."""

from __future__ import annotations

import secrets

#: Characters of the random part of a code: no 0/O, 1/I/L look-alikes.
CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
CODE_RANDOM_CHARS = 12            # 12 × log2(31) = 59 bits, written in groups of four
CODE_GROUP = 4
OLD_CODE_RANDOM_CHARS = 4         # codes made before: still accepted


class StoreError(ValueError):
    """A code is malformed or unknown, or the database cannot be used (one line)."""


class StoreUnavailable(StoreError):
    """The database cannot be read or written now (full disk, damaged file, another layout,
    an unreachable server): a tab keeps its settings and tries again later."""


def code_prefix(exercise: str) -> str:
    """Two letters from the exercise name: its first and last word's initials
    (``kalman_noise`` -> ``KN``, ``lqg_vs_pid`` -> ``LP``)."""
    words = [w for w in exercise.split("_") if w] or ["X"]
    return (words[0][0] + (words[-1][0] if len(words) > 1 else words[0][-1])).upper()


def grouped(prefix: str, random_part: str) -> str:
    """A code as stored and shown: the prefix, then the random part in groups of ``CODE_GROUP``."""
    groups = [random_part[k:k + CODE_GROUP] for k in range(0, len(random_part), CODE_GROUP)]
    return "-".join([prefix, *groups])


def new_code(prefix: str) -> str:
    """A fresh random code with ``prefix`` (the caller retries when it is taken)."""
    return grouped(prefix, "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_RANDOM_CHARS)))


def normalise_code(text: str, what: str = "experiment") -> str:
    """A code as typed (any case, spaces, dashes or none) in its stored form, or ``StoreError``; a code
    of the right shape with characters no code holds names them (issue 25: "ZZ-0000")."""
    compact = "".join(str(text).split()).upper().replace("_", "").replace("-", "")
    prefix, rest = compact[:2], compact[2:]
    shown = str(text).strip()[:40]
    if not (len(prefix) == 2 and prefix.isascii() and prefix.isalpha()
            and len(rest) in (CODE_RANDOM_CHARS, OLD_CODE_RANDOM_CHARS)):
        raise StoreError(f"{shown!r} is not an {what} code: expected two letters and {CODE_RANDOM_CHARS} "
                         f"characters, e.g. KN-7Q3M-X9TA-HPRW (older codes: KN-7Q3M)")
    foreign = sorted(set(rest) - set(CODE_ALPHABET))
    if foreign:                           # the right shape, but characters a code never holds
        left_out = sorted(set("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ") - set(CODE_ALPHABET))
        raise StoreError(f"{shown!r} is not an {what} code: codes never contain {', '.join(foreign)} "
                         f"({', '.join(left_out[:-1])} and {left_out[-1]} look alike and are left out)")
    return grouped(prefix, rest)
