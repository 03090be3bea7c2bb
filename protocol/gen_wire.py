#!/usr/bin/env python3
"""Generates the wire format's constants from protocol/wire.toml (docs/protocol.md).

  gen_wire.py --cpp OUT.h          protocol/wire.h for protocol/protocol.{h,cpp} (CMake, at build time)
  gen_wire.py --js OUT.js          web/src/net/Wire.js for Protocol.js (committed)
  gen_wire.py --check-js FILE.js   exit 1 unless FILE.js is exactly what --js writes (CTest protocol_wire_js)

The JavaScript also carries two sets of values that live in C++ headers rather than in
wire.toml, read from there so they too are declared once: the client-visible error codes
(protocol/protocol.h's ErrorCode up to kMaxErrorCode) and the numerical bounds of transforms,
points and directions (core/validate.h, which also bounds glTF scenes).
"""
import argparse
import math
import os
import re
import struct
import sys

if sys.version_info < (3, 11):
    sys.exit("gen_wire.py: needs Python 3.11 or later (tomllib)")
import tomllib  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPEC = os.path.join(ROOT, "protocol", "wire.toml")
PROTOCOL_H = os.path.join(ROOT, "protocol", "protocol.h")
VALIDATE_H = os.path.join(ROOT, "core", "validate.h")

SIZES = {"u8": 1, "u16": 2, "u32": 4, "u64": 8, "f32": 4, "vec3": 12, "mat4": 64, "u8x3": 3}
TAILS = ("bytes", "string")
FLOAT_TYPES = ("f32", "vec3", "mat4")
RANGE_KEYS = ("range", "open", "above", "non_negative", "finite", "min")
KNOWN = {"name", "type", "js", "id", "reserved", "enum", "flag", "flags", "range", "open", "above",
         "non_negative", "finite", "error", "limit", "min", "max_length", "length", "doc", "transform"}
ERRORS = {"out_of_range", "bad_components"}


def fail(msg):
    sys.exit(f"gen_wire.py: {msg}")


def f32(x):
    """x rounded to the nearest float, as a Python float (exact)."""
    if x == "pi":
        x = math.pi
    return struct.unpack("<f", struct.pack("<f", float(x)))[0]


def cpp_float(x):
    v = f32(x)
    text = repr(v)
    if "e" not in text and "." not in text:
        text += ".0"
    return text + "f"


def camel(name):
    head, *rest = name.split("_")
    return head + "".join(p[:1].upper() + p[1:] for p in rest)


def load():
    with open(SPEC, "rb") as fh:
        spec = tomllib.load(fh)
    enums = spec["enums"]
    names = set()
    for rec in spec["record"]:
        if rec["name"] in names:
            fail(f"record {rec['name']} declared twice")
        names.add(rec["name"])
        offset = 0
        seen = set()
        for i, f in enumerate(rec["fields"]):
            unknown = set(f) - KNOWN
            if unknown:
                fail(f"{rec['name']}.{f['name']}: unknown attributes {sorted(unknown)}")
            if f["name"] in seen:
                fail(f"{rec['name']}.{f['name']} declared twice")
            seen.add(f["name"])
            t = f["type"]
            if t in TAILS:
                if i != len(rec["fields"]) - 1:
                    fail(f"{rec['name']}.{f['name']}: a {t} field must be the last")
                if "length" in f and f["length"] not in seen:
                    fail(f"{rec['name']}.{f['name']}: length names no earlier field")
            elif t not in SIZES:
                fail(f"{rec['name']}.{f['name']}: unknown type {t}")
            if "enum" in f and f["enum"] not in enums:
                fail(f"{rec['name']}.{f['name']}: unknown enum {f['enum']}")
            if "flags" in f and f["flags"] not in spec["flags"]:
                fail(f"{rec['name']}.{f['name']}: unknown flags {f['flags']}")
            if "limit" in f and f["limit"] not in spec["limits"]:
                fail(f"{rec['name']}.{f['name']}: unknown limit {f['limit']}")
            if f.get("error", "out_of_range") not in ERRORS:
                fail(f"{rec['name']}.{f['name']}: unknown error class {f['error']}")
            if any(k in f for k in ("open", "above", "non_negative", "finite")) and t not in FLOAT_TYPES:
                fail(f"{rec['name']}.{f['name']}: float rule on a {t}")
            f["offset"] = offset
            if t not in TAILS:
                offset += SIZES[t]
        rec["fixed"] = offset
        rec["tail"] = rec["fields"][-1]["type"] in TAILS
    return spec


def error_codes():
    text = open(PROTOCOL_H, encoding="utf-8").read()
    m = re.search(r"enum class ErrorCode\s*:\s*uint16_t\s*\{(.*?)\};", text, re.S)
    mx = re.search(r"constexpr uint16_t kMaxErrorCode = (\d+);", text)
    if not m or not mx:
        fail("protocol/protocol.h: no ErrorCode enum or kMaxErrorCode")
    codes = {}
    for name, value in re.findall(r"^\s*(\w+)\s*=\s*(\d+)\s*,", m.group(1), re.M):
        codes[int(value)] = name
    top = int(mx.group(1))
    wire = [codes.get(i) for i in range(top + 1)]
    if None in wire:
        fail("protocol/protocol.h: ErrorCode values 0..kMaxErrorCode are not contiguous")
    return wire


def validate_bounds():
    text = open(VALIDATE_H, encoding="utf-8").read()

    def limits(name):
        m = re.search(r"constexpr TransformLimits " + name + r"\{([^}]*)\};", text)
        if not m:
            fail(f"core/validate.h: no {name}")
        values = [float(v) for v in m.group(1).split(",")]
        if len(values) != 4:
            fail(f"core/validate.h: {name} does not hold 4 values")
        return dict(zip(("maxNorm", "maxInverseNorm", "maxCondition", "maxTranslation"), values))

    def scalar(name):
        m = re.search(r"constexpr float " + name + r" = ([0-9.eE+-]+)f;", text)
        if not m:
            fail(f"core/validate.h: no {name}")
        return f32(m.group(1))

    return {"MESH_TRANSFORM": limits("kMeshLimits"), "CAMERA_TRANSFORM": limits("kCameraLimits"),
            "WORLD_LIMIT": scalar("kWorldLimit"), "UNIT_TOLERANCE": scalar("kUnitTolerance")}


# ---------------------------------------------------------------------------------------
# C++

CPP_TYPES = {"u32": "uint32_t", "i32": "int32_t", "u64": "uint64_t"}


def cpp_int(v, t):
    return f"{v}ull" if t == "u64" else (f"{v}u" if t == "u32" else str(v))


def gen_cpp(spec):
    out = []
    w = out.append
    w("#pragma once")
    w("// Generated by protocol/gen_wire.py from protocol/wire.toml: do not edit; change wire.toml.")
    w("// The wire format's enums, flags, body sizes, field offsets, ranges and default limits")
    w("// (docs/protocol.md). protocol/protocol.h includes it.")
    w("#include <cstddef>")
    w("#include <cstdint>")
    w("")
    w('#include "core/math.h"')
    w('#include "core/scene.h"')
    w("")
    w("namespace tessera::protocol {")
    w("")
    magic = spec["magic"]
    w(f"constexpr uint8_t kVersion = {spec['version']};")
    w(f"constexpr uint8_t kMagic0 = '{magic[0]}', kMagic1 = '{magic[1]}';")
    w(f"constexpr size_t kMessageHeaderSize = {spec['message_header']};")
    w(f"constexpr size_t kRecordHeaderSize = {spec['record_header']};")
    w(f"constexpr uint32_t kNoRecord = {spec['no_record']:#x}u;")
    w("")
    w("// Record types: client -> server below 0x80, server -> client from 0x80.")
    w("enum class RecordType : uint8_t {")
    for rec in spec["record"]:
        w(f"  {rec['name']} = {rec['code']:#04x},  // {rec['channel']}")
    w("};")
    for key, e in spec["enums"].items():
        if e.get("owner") == "core":
            continue
        vals = ", ".join(f"{v} = {i}" for i, v in enumerate(e["values"]))
        w(f"enum class {e['cpp']} : uint8_t {{ {vals} }};")
    w("")
    for group, bits in spec["flags"].items():
        for name, bit in bits.items():
            w(f"constexpr uint8_t k{camel(group).capitalize()}{camel(name)[:1].upper()}{camel(name)[1:]} = {bit};")
    w("")
    w("namespace wire {")
    w("")
    w("// The kinds of range a field is checked against (protocol.cpp's Check picks the rule by kind).")
    w("struct Closed { float lo, hi; };      // finite, lo <= v <= hi")
    w("struct Open { float lo, hi; };        // finite, lo < v < hi")
    w("struct Above { float lo; };           // finite, v > lo")
    w("struct IntRange { uint32_t lo, hi; };  // lo <= v <= hi")
    w("")
    w(f"constexpr size_t kRemoveBody = {spec['remove_body']};")
    w("")
    w("// protocol::Limits' defaults.")
    w("namespace limits {")
    for name, l in spec["limits"].items():
        w(f"constexpr {CPP_TYPES[l['type']]} {name} = {cpp_int(l['value'], l['type'])};  // {l['doc']}")
    w("}  // namespace limits")
    w("")
    w("// The largest value of each enum.")
    w("namespace enum_max {")
    for key, e in spec["enums"].items():
        w(f"constexpr uint8_t {key} = {len(e['values']) - 1};")
    w("}  // namespace enum_max")
    for rec in spec["record"]:
        w("")
        tail = " (then the payload)" if rec["tail"] else ""
        w(f"namespace {rec['name']} {{")
        w(f"constexpr size_t kFixed = {rec['fixed']};  // body bytes before any payload{tail}")
        w(f"constexpr bool kRemovable = {'true' if rec.get('removable') else 'false'};")
        w("namespace at {  // field offsets in the body")
        for f in rec["fields"]:
            w(f"constexpr size_t {f['name']} = {f['offset']};")
        w("}  // namespace at")
        for f in rec["fields"]:
            n = f["name"]
            if "range" in f and f["type"] in FLOAT_TYPES:
                lo, hi = f["range"]
                w(f"constexpr Closed {n}{{{cpp_float(lo)}, {cpp_float(hi)}}};")
            elif "range" in f:
                lo, hi = f["range"]
                w(f"constexpr IntRange {n}{{{lo}, {hi}}};")
            elif "min" in f:
                w(f"constexpr IntRange {n}{{{f['min']}, 0xffffffffu}};")
            elif "open" in f:
                lo, hi = f["open"]
                w(f"constexpr Open {n}{{{cpp_float(lo)}, {cpp_float(hi)}}};")
            elif "above" in f:
                w(f"constexpr Above {n}{{{cpp_float(f['above'])}}};")
            if "max_length" in f:
                w(f"constexpr size_t {n}_max_length = {f['max_length']};")
        w(f"}}  // namespace {rec['name']}")
    w("")
    w("// The channel a record type belongs to, and whether op remove is defined for it.")
    w("constexpr bool known_record(uint8_t type, Channel channel) {")
    w("  switch (RecordType(type)) {")
    for ch in ("client", "server"):
        for rec in spec["record"]:
            if rec["channel"] == ch:
                w(f"    case RecordType::{rec['name']}:")
        w(f"      return channel == Channel::{ch};")
    w("  }")
    w("  return false;")
    w("}")
    w("constexpr bool removable(RecordType type) {")
    w("  switch (type) {")
    for rec in spec["record"]:
        if rec.get("removable"):
            w(f"    case RecordType::{rec['name']}:")
    w("      return true;")
    w("    default:")
    w("      return false;")
    w("  }")
    w("}")
    w("")
    w("}  // namespace wire")
    w("")
    w("// core/scene.h's enums hold the values the wire declares.")
    for key, e in spec["enums"].items():
        if e.get("owner") != "core":
            continue
        for i, v in enumerate(e["values"]):
            w(f"static_assert(uint8_t({e['cpp']}::{v}) == {i}, \"wire.toml: {key} {v}\");")
    w('static_assert(wire::camera::fov_y.hi == kPi, "wire.toml: pi is core/math.h\'s kPi");')
    w("")
    w("}  // namespace tessera::protocol")
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------------------
# JavaScript


def js_value(v):
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int,)):
        return str(v)
    if isinstance(v, float):
        if v == int(v) and abs(v) < 2**53:
            return str(int(v))
        return repr(v)
    if isinstance(v, str):
        return "'" + v.replace("\\", "\\\\").replace("'", "\\'") + "'"
    if isinstance(v, list):
        return "[" + ", ".join(js_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k}: {js_value(x)}" for k, x in v.items()) + " }"
    fail(f"no JavaScript for {v!r}")


def js_field(rec, f):
    d = {"name": f["name"], "type": f["type"], "offset": f["offset"]}
    js = f.get("js", camel(f["name"]))
    d["js"] = js if js is not False else None
    for k in ("id", "reserved", "enum", "flag", "flags", "limit", "min", "error", "max_length", "length",
              "non_negative", "finite", "transform"):
        if k in f:
            d[camel(k)] = f[k]
    if "range" in f:
        lo, hi = f["range"]
        d["range"] = {"kind": "closed", "lo": f32(lo), "hi": f32(hi)} if f["type"] in FLOAT_TYPES else \
            {"kind": "int", "lo": lo, "hi": hi}
    if "open" in f:
        lo, hi = f["open"]
        d["range"] = {"kind": "open", "lo": f32(lo), "hi": f32(hi)}
    if "above" in f:
        d["range"] = {"kind": "above", "lo": f32(f["above"])}
    return d


def gen_js(spec):
    out = []
    w = out.append
    w("// Generated by protocol/gen_wire.py from protocol/wire.toml (and protocol/protocol.h's ErrorCode,")
    w("// core/validate.h's bounds): do not edit. Change wire.toml, then run")
    w("//   python3 protocol/gen_wire.py --js web/src/net/Wire.js")
    w("// CTest protocol_wire_js fails while this file differs from what that writes.")
    w("")
    w(f"export const VERSION = {spec['version']};")
    w(f"export const MAGIC = [{', '.join(hex(ord(c)) for c in spec['magic'])}];  // \"{spec['magic']}\"")
    w(f"export const MESSAGE_HEADER = {spec['message_header']};")
    w(f"export const RECORD_HEADER = {spec['record_header']};")
    w(f"export const NO_RECORD = {spec['no_record']:#x};")
    w(f"export const REMOVE_BODY = {spec['remove_body']};")
    w("")
    w("// protocol::Limits' defaults, under the C++ names.")
    w("export const LIMITS = Object.freeze({")
    for name, l in spec["limits"].items():
        w(f"  {name}: {l['value']},  // {l['doc']}")
    w("});")
    w("")
    w("// Enums: the value on the wire is the index of the name.")
    w("export const ENUMS = Object.freeze({")
    for key, e in spec["enums"].items():
        w(f"  {key}: Object.freeze({js_value(e['values'])}),")
    w("});")
    for key, e in spec["enums"].items():
        w(f"export const {e['js']} = ENUMS.{key};")
    w("")
    w("export const FLAGS = Object.freeze({")
    for group, bits in spec["flags"].items():
        w(f"  {group}: Object.freeze({js_value(bits)}),")
    w("});")
    w("")
    w("// Every record: its type code, channel, body bytes before any payload, and its fields in wire")
    w("// order with their offsets and rules (range bounds are the f32 values the decoders compare with).")
    w("export const RECORDS = Object.freeze({")
    for rec in spec["record"]:
        w(f"  {rec['name']}: Object.freeze({{")
        w(f"    code: {rec['code']:#04x}, channel: '{rec['channel']}', fixed: {rec['fixed']}, "
          f"tail: {js_value(rec['tail'])}, removable: {js_value(bool(rec.get('removable')))},")
        w("    fields: Object.freeze([")
        for f in rec["fields"]:
            w(f"      {js_value(js_field(rec, f))},")
        w("    ]),")
        w("  }),")
    w("});")
    w("export const RecordType = Object.freeze(Object.fromEntries(Object.entries(RECORDS).map(([k, r]) => [k, r.code])));")
    w("")
    w("// The ranges of the fields that have one, by record and field name.")
    w("export const RANGES = Object.freeze(Object.fromEntries(Object.entries(RECORDS).map(([k, r]) =>")
    w("  [k, Object.freeze(Object.fromEntries(r.fields.filter((f) => f.range).map((f) => [f.name, f.range])))])));")
    w("")
    w("// protocol/protocol.h's ErrorCode names, by value, up to kMaxErrorCode (the codes on the wire).")
    codes = error_codes()
    w(f"export const ErrorCode = Object.freeze({js_value(codes)});")
    w(f"export const MAX_ERROR_CODE = {len(codes) - 1};")
    w("")
    w("// core/validate.h: the bounds of camera and mesh transforms, points and directions.")
    for name, v in validate_bounds().items():
        w(f"export const {name} = Object.freeze({js_value(v)});" if isinstance(v, dict)
          else f"export const {name} = {js_value(v)};")
    return "\n".join(out) + "\n"


def write(path, text):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    old = open(path, encoding="utf-8").read() if os.path.exists(path) else None
    if old != text:  # keep the time stamp when nothing changed (no rebuilds)
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cpp")
    ap.add_argument("--js")
    ap.add_argument("--check-js")
    a = ap.parse_args()
    spec = load()
    if a.cpp:
        write(a.cpp, gen_cpp(spec))
    if a.js:
        write(a.js, gen_js(spec))
    if a.check_js:
        want = gen_js(spec)
        have = open(a.check_js, encoding="utf-8").read() if os.path.exists(a.check_js) else ""
        if have != want:
            print(f"{a.check_js} differs from what protocol/wire.toml gives; run\n"
                  f"  python3 protocol/gen_wire.py --js {os.path.relpath(a.check_js, ROOT)}")
            return 1
        print(f"{a.check_js}: up to date with protocol/wire.toml")
    return 0


if __name__ == "__main__":
    sys.exit(main())
