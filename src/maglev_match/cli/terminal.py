"""Output on terminals that cannot show every character (``PYTHONIOENCODING=ascii``, a
``LANG=C`` locale): results are never lost to an encoding error.

The command line writes a few non-ASCII characters (an em dash in headers, box-drawing
characters in tables, Greek letters in some warnings). On an output whose encoding lacks
them, Python raises UnicodeEncodeError in the middle of printing, after the whole
computation: `design` once finished its search and then lost the result that way.
:func:`guard_output` gives stdout and stderr an error handler that writes such characters as
ASCII (a dash, ``+/-``, ``lambda``, ``?`` for the rest), and :func:`encoding_note` is the one
warning line, printed once at the end when something was replaced, that names the variable
that chose the encoding and what to set instead.
"""

from __future__ import annotations

import codecs
import os
import sys
import unicodedata

__all__ = ["guard_output", "encoding_note", "ASCII_FALLBACK"]

HANDLER = "maglev_match_ascii"

#: ASCII stand-ins for the characters the command line prints; others become "?".
ASCII_FALLBACK: dict[str, str] = {
    "\u2014": "-", "\u2013": "-", "\u2212": "-", "\u2010": "-", "\u00b1": "+/-",
    "\u2026": "...", "\u2264": "<=", "\u2265": ">=", "\u00d7": "x", "\u00b7": ".",
    "\u00b0": " deg", "\u00b5": "u", "\u03bc": "mu", "\u00b2": "^2", "\u00b3": "^3",
    "\u2018": "'", "\u2019": "'", "\u201c": '"', "\u201d": '"', "\u2192": "->",
    "\u2190": "<-", "\u2248": "~", "\u2022": "*", "\u00a0": " ",
    # box drawing (Rich tables and rules)
    **{c: "-" for c in "\u2500\u2501\u2504\u2505\u2508\u2509\u254c\u254d\u2550\u2574\u2576"},
    **{c: "|" for c in "\u2502\u2503\u2506\u2507\u250a\u250b\u254e\u254f\u2551\u2575\u2577"},
    **{c: "+" for c in "\u250c\u2510\u2514\u2518\u251c\u2524\u252c\u2534\u253c\u256d\u256e"
                       "\u256f\u2570\u2552\u2555\u2558\u255b\u255e\u2561\u2564\u2567\u256a"
                       "\u2554\u2557\u255a\u255d\u2560\u2563\u2566\u2569\u256c\u250f\u2513"
                       "\u2517\u251b\u2523\u252b\u2533\u253b\u254b\u2521\u2529\u2547\u2548"},
}

# Greek letters by name (sigma, omega, Lambda ...): parameter names and units use them
for _cp in range(0x391, 0x3CA):
    _name = unicodedata.name(chr(_cp), "")
    if _name.startswith(("GREEK SMALL LETTER ", "GREEK CAPITAL LETTER ")):
        _word = _name.split(" LETTER ", 1)[1].lower().replace(" ", "_")
        ASCII_FALLBACK[chr(_cp)] = _word if "SMALL" in _name else _word.capitalize()
ASCII_FALLBACK.update({"\u03bb": "lambda", "\u039b": "Lambda",  # Unicode spells LAMDA
                       "\u03c2": "sigma", "\u00b5": "u"})  # final sigma; the micro sign

_replaced: list[str] = []  # the first characters that had to be replaced (for the note)


def _fallback(err: UnicodeError) -> tuple[str, int]:
    if not isinstance(err, UnicodeEncodeError):
        raise err
    text = err.object[err.start:err.end]
    if len(_replaced) < 3:
        _replaced.extend(c for c in text if c not in _replaced)
    return "".join(ASCII_FALLBACK.get(c, "?") for c in text), err.end


codecs.register_error(HANDLER, _fallback)


def _lacks_unicode(stream) -> bool:
    encoding = getattr(stream, "encoding", None)
    if not encoding:
        return False
    try:
        "\u2014\u00b1\u03bb\u2500".encode(encoding)
    except (UnicodeEncodeError, LookupError):
        return True
    return False


def guard_output() -> None:
    """Give stdout and stderr the ASCII fallback handler when their encoding cannot show
    the characters the command line prints (no effect on a UTF-8 output)."""
    for stream in (sys.stdout, sys.stderr):
        if _lacks_unicode(stream) and hasattr(stream, "reconfigure"):
            try:
                stream.reconfigure(errors=HANDLER)
            except (ValueError, OSError):  # a closed or detached stream: leave it
                pass


def _encoding_variable() -> str:
    """NAME=VALUE of the variable that chose the output encoding."""
    if os.environ.get("PYTHONIOENCODING"):
        return f"PYTHONIOENCODING={os.environ['PYTHONIOENCODING']}"
    for name in ("LC_ALL", "LC_CTYPE", "LANG"):
        if os.environ.get(name):
            return f"{name}={os.environ[name]}"
    return "LANG (unset)"


def encoding_note() -> str | None:
    """The warning to print once when characters were replaced, else None."""
    if not _replaced:
        return None
    shown = ", ".join(ascii(c) for c in _replaced[:3])
    encoding = getattr(sys.stdout, "encoding", None) or "?"
    _replaced.clear()
    return (f"{_encoding_variable()}: the output encoding '{encoding}' cannot show some "
            f"characters ({shown}); they were written as ASCII stand-ins or '?': set "
            "PYTHONIOENCODING=utf-8 or a UTF-8 locale (LANG=C.UTF-8) to see them")
