"""CSV tables as labs and spreadsheets write them, read into columns with one-line errors: the importer's input
layer (analysis/importer.py; rules in docs/log-format.md, "Importing CSV measurements").

- Encoding: UTF-8 (a BOM is accepted), UTF-16 with its BOM (a spreadsheet's "Unicode text"); other bytes are read
  as Latin-1, so a stray non-UTF-8 byte in a comment cannot stop an import (the column names are ASCII).
- Line ends: LF, CRLF or CR.
- Delimiter: `,`, `;`, tab or `|`, sniffed from the header line (the one that holds the most required columns) or
  given (`--delimiter`).
- Decimal separator: with a delimiter other than `,`, a decimal comma is accepted (`1,5` = 1.5), as a spreadsheet in
  a European locale writes it; a number with both `.` and `,` is refused (a thousands separator is ambiguous).
- Lines that are empty or whose first cell starts with `#` are skipped; cells are stripped; a blank cell, `nan`,
  `NA` or `N/A` means "not measured"; extra columns are ignored; a row may end in extra EMPTY cells (a trailing
  delimiter) but not in extra values.

Every refusal is a ConfigError of one line naming the file, the 1-based line and the column.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hamr_bench.errors import ConfigError

DELIMITERS = {",": ",", ";": ";", "tab": "\t", "\\t": "\t", "\t": "\t", "|": "|"}
BLANKS = ("", "nan", "na", "n/a")
SNIFF_CHARS = 1 << 16         # the header is sniffed from the start of the file


@dataclass(frozen=True)
class Table:
    """The rows of a CSV table: header (stripped names), rows as (line number, cells padded to the header)."""

    path: Path
    header: list[str]
    rows: list[tuple[int, list[str]]]
    delimiter: str
    decimal_comma: bool

    def has(self, column: str) -> bool:
        return column in self.header

    def cells(self, column: str) -> list[str]:
        """The stripped cells of a column ('' for every row if the column is absent)."""
        if column not in self.header:
            return [""] * len(self.rows)
        j = self.header.index(column)
        return [row[j].strip() for _line, row in self.rows]

    def number(self, line: int, column: str, text: str, *, blank_ok: bool = True, integer: bool = False,
               lo: float | None = None) -> float | None:
        """One cell as a finite number (None for a blank when allowed)."""
        t = text.strip()
        if t.lower() in BLANKS:
            if blank_ok:
                return None
            got = _show(t) if t else "a blank"
            raise ConfigError(f"{self.path}:{line}: column {column}: value required, got {got}")
        v = self._parse(t)
        if v is None:
            raise ConfigError(f"{self.path}:{line}: column {column}: expected a number, got {_show(t)}")
        if not math.isfinite(v):
            raise ConfigError(f"{self.path}:{line}: column {column}: expected a finite number, got {_show(t)}")
        if integer and not v.is_integer():
            raise ConfigError(f"{self.path}:{line}: column {column}: expected an integer, got {_show(t)}")
        if lo is not None and v < lo:
            raise ConfigError(f"{self.path}:{line}: column {column}: expected >= {lo:g}, got {_show(t)}")
        return v

    def _parse(self, t: str) -> float | None:
        if self.decimal_comma and "," in t:
            if "." in t or t.count(",") > 1:
                return None
            t = t.replace(",", ".")
        if "_" in t:          # Python's float() reads 1_000; a CSV number never means that
            return None
        try:
            return float(t)
        except ValueError:
            return None

    def column(self, column: str, *, blank_ok: bool = True) -> np.ndarray:
        """A whole numeric column (nan where blank), refusing the first bad cell with its line."""
        out = np.full(len(self.rows), np.nan)
        for i, (text, (line, _row)) in enumerate(zip(self.cells(column), self.rows, strict=True)):
            v = self.number(line, column, text, blank_ok=blank_ok)
            if v is not None:
                out[i] = v
        return out


def _show(text: str, limit: int = 40) -> str:
    shown = text if len(text) <= limit else text[:limit] + "..."
    return repr(shown)


def _decode(path: Path, data: bytes) -> str:
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{path}: not UTF-16 text after its byte-order mark (byte {exc.start})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _split(path: Path, text: str, delimiter: str) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every non-empty, non-comment line."""
    out = []
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    line = 0
    try:
        for row in reader:
            line_start = line + 1
            line = reader.line_num
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            out.append((line_start, row))
    except csv.Error as exc:
        raise ConfigError(f"{path}:{reader.line_num + 1}: not readable as CSV ({exc})") from None
    return out


def _sniff(path: Path, text: str, required: tuple[str, ...]) -> str:
    """The delimiter whose split of the header line holds the most required columns (then the most cells)."""
    best, best_score = ",", (-1, -1)
    for delimiter in (",", ";", "\t", "|"):
        try:
            rows = _split(path, text[:SNIFF_CHARS], delimiter)
        except ConfigError:
            continue
        if not rows:
            continue
        header = [c.strip() for c in rows[0][1]]
        score = (sum(c in header for c in required), len(header))
        if score > best_score:
            best, best_score = delimiter, score
    return best


def _check_header(path: Path, head_line: int, header: list[str], required: tuple[str, ...], delim: str) -> None:
    """One line naming the file and line when the header lacks a required column or repeats one."""
    missing = [c for c in required if c not in header]
    if missing:
        shown = ", ".join(_show(c, 20) for c in header[:8]) + (", ..." if len(header) > 8 else "")
        raise ConfigError(f"{path}:{head_line}: header lacks column(s) {', '.join(missing)} "
                          f"(expected {', '.join(required)}; read {len(header)} cell(s) split at "
                          f"{'tab' if delim == chr(9) else repr(delim)}: {shown})")
    dupes = sorted({c for c in header if c and header.count(c) > 1})
    if dupes:
        raise ConfigError(f"{path}:{head_line}: column {dupes[0]} appears more than once in the header")


def read_table(path: Path, required: tuple[str, ...], delimiter: str | None = None) -> Table:
    """Read a CSV table whose header must hold `required` (see the module docstring)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot open ({exc.strerror or exc})") from None
    if b"\x00" in data and not data.startswith((b"\xff\xfe", b"\xfe\xff")):
        line = data[:data.index(b"\x00")].count(b"\n") + 1
        raise ConfigError(f"{path}:{line}: a NUL byte: not a text file (a CSV export is text)")
    text = _decode(path, data)
    if delimiter is not None:
        if delimiter not in DELIMITERS:
            raise ConfigError(f"--delimiter {delimiter!r}: expected one of , ; tab |")
        delim = DELIMITERS[delimiter]
    else:
        delim = _sniff(path, text, required)
    rows = _split(path, text, delim)
    if not rows:
        raise ConfigError(f"{path}: empty file (expected a header line with {', '.join(required)})")
    head_line, head = rows[0]
    header = [c.strip() for c in head]
    _check_header(path, head_line, header, required, delim)
    body = []
    for line, row in rows[1:]:
        if len(row) > len(header):
            if any(c.strip() for c in row[len(header):]):
                raise ConfigError(f"{path}:{line}: {len(row)} fields but the header has {len(header)}")
            row = row[:len(header)]
        body.append((line, row + [""] * (len(header) - len(row))))
    if not body:
        raise ConfigError(f"{path}: no data rows after the header")
    return Table(path, header, body, delim, decimal_comma=delim != ",")
