"""The bracket helpers every reader shares, against spans counted by hand."""

from olp_compensate.programs.brackets import argument_spans, closing, line_end, strip_span


def test_closing_counts_nesting_and_stops_at_hi():
    text = "x = {A {B 1}, C 2} tail"
    assert closing(text, 4) == text.index("} tail") + 1
    assert closing(text, 4, hi=12) is None                  # the outer brace is past hi
    assert closing("P[1:[2]] ;", 1, pair="[]") == len("P[1:[2]]")
    assert closing("P[1\n]", 1, line_end("P[1\n]", 1), "[]") is None


def test_argument_spans_top_level_only_and_strings_skipped():
    text = 'movel(p[1, 2], a=1.2 , "x,(")'
    spans, end = argument_spans(text, 5, quote='"')
    assert end == len(text)
    assert [text[a:b] for a, b in spans] == ["p[1, 2]", " a=1.2 ", ' "x,("']
    assert [text[slice(*strip_span(text, a, b))] for a, b in spans] == \
        ["p[1, 2]", "a=1.2", '"x,("']
    spans, end = argument_spans("f(a, b", 1)
    assert end == -1 and spans == [(2, 3)]                   # only the comma-ended one
