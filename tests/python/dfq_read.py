"""Reads a Q-DAS ASCII transfer file (.dfq) and prints what it holds as JSON.

Written from the field list of the Q-DAS ASCII transfer format (AQDEF), independently of
surfscan's writer: each line is `Kxxxx[/i] content`; K0100 is the number of characteristics;
K1xxx describe the part, K2xxx/i characteristic i; in the value part each K0001/i starts a new
value of characteristic i and the K00xx/i fields after it (date/time K0004, batch K0006,
operator K0008, text K0009, part ident K0014) belong to that value. The text is ISO 8859-1, lines end with
CR LF.

Usage: dfq_read.py FILE  -> {"K0100": n, "part": {...}, "characteristics": {i: {...}},
                             "values": {i: [{...}]}}
"""
import json
import sys
from datetime import datetime


def number(s):
    return float(s)


def main(path):
    raw = open(path, "rb").read()
    if not raw.endswith(b"\r\n"):
        raise SystemExit("the last line does not end with CR LF")
    text = raw.decode("latin-1")
    lines = text.split("\r\n")[:-1]
    out = {"K0100": None, "part": {}, "characteristics": {}, "values": {}}
    for n, line in enumerate(lines, 1):
        if "\n" in line or "\r" in line:
            raise SystemExit(f"line {n}: a bare CR or LF")
        key, _, content = line.partition(" ")
        if len(key) < 5 or key[0] != "K" or not key[1:5].isdigit():
            raise SystemExit(f"line {n}: not a K field: {line!r}")
        field, _, index = key.partition("/")
        code = int(field[1:5])
        i = int(index) if index else None
        if field == "K0100":
            if n != 1:
                raise SystemExit("K0100 is not the first line")
            out["K0100"] = int(content)
        elif 1000 <= code < 2000:
            out["part"][field] = content
        elif 2000 <= code < 3000:
            if i is None:
                raise SystemExit(f"line {n}: a characteristic field without /i")
            c = out["characteristics"].setdefault(str(i), {})
            if field in ("K2101", "K2110", "K2111"):
                c[field] = number(content)
            else:
                c[field] = content
        elif code < 100:
            if i is None:
                raise SystemExit(f"line {n}: a value field without /i")
            vals = out["values"].setdefault(str(i), [])
            if field == "K0001":
                vals.append({"K0001": number(content)})
            else:
                if not vals:
                    raise SystemExit(f"line {n}: {field}/{i} before any K0001/{i}")
                if field == "K0004":
                    # DD.MM.YYYY/HH:MM:SS
                    t = datetime.strptime(content, "%d.%m.%Y/%H:%M:%S")
                    vals[-1][field] = t.strftime("%Y-%m-%dT%H:%M:%S")
                else:
                    vals[-1][field] = content
        else:
            raise SystemExit(f"line {n}: unexpected field {field}")
    if out["K0100"] != len(out["characteristics"]):
        raise SystemExit("K0100 does not match the characteristics described")
    json.dump(out, sys.stdout, ensure_ascii=False)


if __name__ == "__main__":
    main(sys.argv[1])
