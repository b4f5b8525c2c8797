"""A result's warnings as a reader takes them in: those that a parameter is poorly determined said in one line
(:func:`grouped_warnings`), for the terminal and the report, whose tables show each std; the JSON keeps each."""

from __future__ import annotations

from collections.abc import Sequence

#: The words of a warning that a parameter is poorly determined: compare's table shows each std, so the names suffice.
_POORLY = " is poorly determined by this log"
#: The same said of several logs combined (``--given``).
_POORLY_ALL = " is poorly determined by these logs"


def grouped_warnings(warnings: Sequence[str]) -> list[str]:
    """A result's warnings for the terminal and the report: those that a parameter is poorly determined by the log
    (one each, with the value and std that the table shows) said in one line naming the parameters, where the first
    was; what a warning adds beyond the table (the parameters it cannot be told apart from) stays with its name.  The
    JSON keeps each."""
    out: list[str] = []
    for words, said in ((_POORLY, "this log"), (_POORLY_ALL, "these logs")):
        poorly = [_poorly_name(w, words) for w in warnings if words in w]
        if poorly:
            joined = "; ".join(poorly) if any("," in p for p in poorly) else ", ".join(poorly)
            out.append(f"poorly determined by {said} (std in the table): {joined}")
    first = next((i for i, w in enumerate(warnings) if _POORLY in w or _POORLY_ALL in w), len(warnings))
    rest = [w for w in warnings if _POORLY not in w and _POORLY_ALL not in w]
    return [*rest[:first], *out, *rest[first:]]


def _poorly_name(warning: str, words: str) -> str:
    """ "Fv1, not separable from Fd1 (correlation 0.97)" of "Fv1 is poorly determined by this log: 4.8 +/- 40 PWM s/rad;
    it is not separable from Fd1 (correlation 0.97)"; the name alone when the warning adds nothing to the table."""
    name = warning.split(words, 1)[0]
    _, _, beyond = warning.partition("; it is ")
    return f"{name}, {beyond}" if beyond else name
