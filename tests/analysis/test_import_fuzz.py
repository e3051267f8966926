"""The importer under random input: random bytes, random valid-ish CSV tables, and dialect mixes (delimiter,
decimal comma, BOM, CRLF, quoting, extra columns, blank and garbage cells). Every input either imports (and the
recording then reads back, steps and all) or is refused with ONE ConfigError line naming the file; nothing else
escapes (no traceback, no other exception type). Plus: one table written in every dialect imports to the same
numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from analysis.dataset import load_dataset
from analysis.importer import POINT_COLUMNS, import_points, import_trace
from hamr_bench.cli import main
from hamr_bench.errors import ConfigError
from hamr_bench.recording import RecordingReader

FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                       HealthCheck.too_slow])
TRACE_HEADER = ("time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m")


def _attempt(fn, path, out, **kw) -> bool:
    """True if the import succeeded; a refusal must be one line naming the file."""
    try:
        fn(path, out, overwrite=True, **kw)
    except ConfigError as exc:
        message = str(exc)
        assert "\n" not in message and message.strip(), message
        assert path.name in message or "--" in message, message
        event("refused")
        return False
    event("imported")
    return True


def _check_readable(out) -> None:
    reader = RecordingReader(out)
    assert reader.exit_status == "success"
    load_dataset([out])   # the readers take what the importer wrote


@FUZZ
@given(data=st.binary(max_size=600), fmt=st.sampled_from(["trace", "points"]))
def test_random_bytes_import_or_give_one_line(tmp_path, data, fmt):
    path = tmp_path / "in.csv"
    path.write_bytes(data)
    out = tmp_path / "out.mcap"
    if fmt == "trace":
        ok = _attempt(import_trace, path, out, protocol="actuator")
    else:
        ok = _attempt(import_points, path, out)
    if ok:
        _check_readable(out)


_garbage = st.sampled_from(["", "abc", "nan", "NA", "inf", "-inf", "1e400", "1,5", "1.5,2", "1_000", " 3 ",
                            "\"q\"", "#", "1.0.0", "0x10", "--1", "+2", "é", "\u00a0", "1e-300"])


def _number_text(x: float, decimal_comma: bool) -> str:
    text = repr(float(x))
    return text.replace(".", ",") if decimal_comma else text


@st.composite
def trace_tables(draw):
    """A plausible trace (drive trapezoids at a few levels) with random dialect and random damage."""
    rate = draw(st.sampled_from([200.0, 500.0, 1000.0]))
    dl, ramp, dh = (draw(st.floats(0.02, 0.3)) for _ in range(3))
    cycles = draw(st.integers(1, 3))
    levels = draw(st.lists(st.floats(5.0, 250.0), min_size=1, max_size=3))
    noise = draw(st.sampled_from([0.0, 0.3, 2.0]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    rows: list[list[str | float]] = []
    t0 = 0.0
    specimens = draw(st.sampled_from([None, ["1"], ["A", "B"], ["1", "1.0"]]))
    for k, level in enumerate(levels):
        period = dl + 2 * ramp + dh
        t = np.arange(0.0, cycles * period + 0.1, 1.0 / rate)
        x = np.mod(t, period)
        v = level * np.interp(x, [0, dl, dl + ramp, dl + ramp + dh, period], [0, 0, 1, 1, 0])
        v[t > cycles * period] = 0.0
        v = v + rng.normal(0, noise, v.size) if noise else v
        f = np.maximum(8e-4 * (2 * v - level), 0.0)
        spec = specimens[min(k, len(specimens) - 1)] if specimens else None
        restart = draw(st.booleans()) and spec is not None
        base = 0.0 if restart else t0
        for ti, vi, fi in zip(t, v, f, strict=True):
            rows.append([base + ti, vi, "", fi, "", spec or ""])
        t0 = base + t[-1] + 0.5
    for _ in range(draw(st.integers(0, 3))):   # damage
        r = draw(st.integers(0, len(rows) - 1))
        c = draw(st.integers(0, 5))
        rows[r][c] = draw(_garbage)
    return rows, specimens is not None


@st.composite
def dialects(draw):
    delimiter = draw(st.sampled_from([",", ";", "\t", "|"]))
    return {"delimiter": delimiter, "decimal_comma": delimiter != "," and draw(st.booleans()),
            "bom": draw(st.booleans()), "newline": draw(st.sampled_from(["\n", "\r\n", "\r"])),
            "quote": draw(st.booleans()), "extra": draw(st.booleans()), "trailing": draw(st.booleans()),
            "comment": draw(st.booleans())}


def _write(path, header, rows, d) -> None:
    def cell(x) -> str:
        text = _number_text(x, d["decimal_comma"]) if isinstance(x, float) else str(x)
        if d["quote"] or d["delimiter"] in text or "\"" in text:
            text = "\"" + text.replace("\"", "\"\"") + "\""
        return text

    head = list(header) + (["notes"] if d["extra"] else [])
    lines = ([f"# exported {d['delimiter']!r}"] if d["comment"] else []) + [d["delimiter"].join(head)]
    for r in rows:
        cells = [cell(x) for x in r] + (["x"] if d["extra"] else [])
        lines.append(d["delimiter"].join(cells) + (d["delimiter"] if d["trailing"] else ""))
    text = d["newline"].join(lines) + d["newline"]
    path.write_bytes(("\ufeff" if d["bom"] else "").encode() + text.encode("utf-8"))


@FUZZ
@given(table=trace_tables(), d=dialects())
def test_random_trace_tables_in_any_dialect_import_or_give_one_line(tmp_path, table, d):
    rows, with_specimen = table
    header = TRACE_HEADER + (("specimen",) if with_specimen else ("comment",))
    path = tmp_path / "trace.csv"
    _write(path, header, rows, d)
    out = tmp_path / "trace.mcap"
    if _attempt(import_trace, path, out, protocol="actuator"):
        _check_readable(out)


@st.composite
def point_tables(draw):
    rows = []
    for _ in range(draw(st.integers(1, 6))):
        protocol = draw(st.sampled_from(["actuator", "blocked-force", "static", "free-displacement", "sag-sweep"]))
        design = "" if protocol == "actuator" else str(draw(st.integers(1, 5)))
        rows.append([protocol, design, float(draw(st.integers(1, 3))), draw(st.floats(0, 300)),
                     draw(st.floats(0, 1e-3)), float(draw(st.integers(0, 3))),
                     draw(st.floats(0, 0.3)), draw(st.floats(0, 2e-4)), draw(st.sampled_from(["", "s1", "2"]))])
    for _ in range(draw(st.integers(0, 2))):
        r = draw(st.integers(0, len(rows) - 1))
        rows[r][draw(st.integers(0, 8))] = draw(_garbage)
    return rows


@FUZZ
@given(rows=point_tables(), d=dialects())
def test_random_point_tables_in_any_dialect_import_or_give_one_line(tmp_path, rows, d):
    path = tmp_path / "points.csv"
    _write(path, POINT_COLUMNS + ("specimen",), rows, d)
    out = tmp_path / "points.mcap"
    if _attempt(import_points, path, out):
        _check_readable(out)


def _clean_trace_rows() -> list[list]:
    rate, rows = 500.0, []
    for level in (120.0, 240.0):
        t = np.arange(0.0, 2.0, 1 / rate)
        x = np.mod(t, 0.6)
        v = level * np.interp(x, [0, 0.2, 0.25, 0.55, 0.6], [0, 0, 1, 1, 0])
        v[t > 1.8] = 0.0
        start = rows[-1][0] + 0.5 if rows else 0.0
        rows += [[start + ti, vi, "", max(8e-4 * (2 * vi - level), 0.0), ""] for ti, vi in zip(t, v, strict=True)]
    return rows


@pytest.mark.parametrize("delimiter, decimal_comma, bom, newline", [
    (",", False, False, "\n"), (";", True, True, "\r\n"), ("\t", True, False, "\r\n"), ("|", False, True, "\r"),
    (";", False, False, "\n")])
def test_one_table_in_every_dialect_imports_to_the_same_numbers(tmp_path, delimiter, decimal_comma, bom, newline):
    d = {"delimiter": delimiter, "decimal_comma": decimal_comma, "bom": bom, "newline": newline, "quote": False,
         "extra": True, "trailing": False, "comment": True}
    path = tmp_path / "lab.csv"
    _write(path, TRACE_HEADER, _clean_trace_rows(), d)
    out = tmp_path / "lab.mcap"
    assert import_trace(path, out, "actuator") == 2
    obs = sorted((o.voltage_V, o.value) for o in load_dataset([out]).observations)
    assert [round(v) for v, _ in obs] == [120, 240]
    for v, f in obs:
        assert math.isclose(f, 8e-4 * v, rel_tol=1e-9)


def test_a_semicolon_file_is_not_refused_for_its_header(tmp_path):
    # the report: a ';' export got "header lacks column(s) time_s, ..." for a header that has them all
    path = tmp_path / "excel.csv"
    rows = _clean_trace_rows()
    text = ";".join(TRACE_HEADER) + "\r\n" + "".join(
        ";".join(_number_text(x, True) if isinstance(x, float) else str(x) for x in r) + "\r\n" for r in rows)
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert main(["import", "trace", str(path), "--protocol", "actuator", "--layers", "2", "--out",
                 str(tmp_path / "x.mcap")]) == 0
    # and --delimiter says how to read it when sniffing is not wanted
    assert main(["import", "trace", str(path), "--protocol", "actuator", "--delimiter", ";", "--out",
                 str(tmp_path / "y.mcap")]) == 0


def test_a_malformed_semicolon_row_names_file_line_and_column(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text("time_s;voltage_V;force_N\n0,0;0,0;0,0\n0,001;1,5.2;0,0\n")
    assert main(["import", "trace", str(path), "--protocol", "actuator", "--out", str(tmp_path / "b.mcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{path}:3" in err[0] and "column voltage_V" in err[0]


def test_specimen_rows_must_be_contiguous(tmp_path):
    path = tmp_path / "mixed.csv"
    rows = _clean_trace_rows()
    lines = [",".join(TRACE_HEADER + ("specimen",))]
    for i, r in enumerate(rows):
        label = "A" if i < 300 or i > 900 else "B"
        lines.append(",".join(repr(float(x)) if isinstance(x, float) else str(x) for x in r) + f",{label}")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=r"mixed.csv:903: column specimen: specimen 'A' again"):
        import_trace(path, tmp_path / "m.mcap", "actuator")
