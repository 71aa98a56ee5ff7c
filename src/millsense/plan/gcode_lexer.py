"""Tokeniser for RS274/NGC blocks: one source line → its words.

A block is an optional block-delete slash, words (a letter followed by a number), comments in
parentheses and a comment after ``;``. Spaces and tabs between and inside words are ignored and
letters are case-insensitive (RS274/NGC v3 §3.3). A trailing ``*`` (Heidenhain ISO block end)
is accepted. Expressions, parameters (``#``), O-word subroutines and anything else that is not
a word raise :class:`~millsense.core.errors.ProgramError` naming the file, line and text.
"""

from __future__ import annotations

import re

from millsense.core.errors import ProgramError

#: A parenthesised comment (no nesting) or everything from ';' to the end of the line;
#: whichever comes first wins, so ';' inside parentheses and '(' after ';' are comments.
_COMMENTS = re.compile(r"\([^()]*\)|;.*")
#: A word, or (group 3) any other character, which is garbage.
_WORDS = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))|(.)")

#: Letters that can carry a number in the supported subset.
KNOWN_LETTERS = frozenset("ACDFGHIJKMNPQRSTXYZ")


def program_error(source: str, lineno: int, text: str, reason: str) -> ProgramError:
    """The one-line error for a bad block: ``file:line: reason: 'text'``."""
    return ProgramError(f"{source}:{lineno}: {reason}: '{text.strip()}'")


def strip_block(raw: str, source: str, lineno: int) -> str:
    """Remove comments and blanks from one line and upper-case it.

    Parameters
    ----------
    raw : str
        The source line (without its newline).
    source : str
        File name, for messages.
    lineno : int
        1-based line number, for messages.

    Returns
    -------
    str
        The words of the block without spaces, e.g. ``"/N10G1X1.5"``; empty for a blank or
        comment-only line.
    """
    s = raw
    if "(" in s or ";" in s or ")" in s:
        s = _COMMENTS.sub("", s)
        if "(" in s or ")" in s:
            raise program_error(source, lineno, raw, "unbalanced or nested comment parentheses")
    if " " in s:
        s = s.replace(" ", "")
    if "\t" in s:
        s = s.replace("\t", "")
    s = s.upper()
    if s.endswith("*"):
        s = s[:-1]
    return s


def tokens(block: str) -> list[tuple[str, str, str]]:
    """Raw ``(letter, number, garbage)`` triples of a stripped block (one regex pass).

    A non-empty third element is a character that belongs to no word; pass it to
    :func:`garbage_error`.
    """
    return _WORDS.findall(block)


def garbage_error(block: str, bad: str, raw: str, source: str, lineno: int) -> ProgramError:
    """The error for a character that is not part of a word."""
    if "#" in block:
        reason = "parameters (#) are not supported"
    elif "[" in block:
        reason = "expressions ([...]) are not supported"
    elif bad.isalpha():
        reason = f"letter {bad} without a number"
    else:
        reason = f"unexpected character {bad!r}"
    return program_error(source, lineno, raw, reason)


def words(block: str, raw: str, source: str, lineno: int) -> list[tuple[str, str]]:
    """Split a stripped block (from :func:`strip_block`) into ``(letter, number)`` pairs.

    Raises
    ------
    ProgramError
        On any character that is not part of a word (garbage, ``#`` parameters, ``[``
        expressions, a letter without a number, a number without a letter).
    """
    out: list[tuple[str, str]] = []
    for letter, number, bad in _WORDS.findall(block):
        if bad:
            raise garbage_error(block, bad, raw, source, lineno)
        out.append((letter, number))
    return out
