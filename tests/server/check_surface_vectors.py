#!/usr/bin/env python3
"""Decodes the shared surface test vectors (surface_vectors_test.cc) with a
decoder written here from service.proto's Watch documentation alone (its own
protobuf wire reader, no generated code), as a decoder in another language
(the browser viewer's) would, and checks it reaches exactly what
expected.json says after every frame: positions, fields, quads, counts.

  check_surface_vectors.py DIR   (DIR holds frames.bin and expected.json)
"""
import json
import os
import struct
import sys


def varint(buf, at):
    shift = value = 0
    while True:
        b = buf[at]
        at += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return value, at


def fields(buf):
    """(field number, wire type, value) of each field of a message."""
    at = 0
    while at < len(buf):
        key, at = varint(buf, at)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, at = varint(buf, at)
        elif wire == 1:
            value, at = buf[at:at + 8], at + 8
        elif wire == 2:
            size, at = varint(buf, at)
            value, at = buf[at:at + size], at + size
        elif wire == 5:
            value, at = buf[at:at + 4], at + 4
        else:
            raise ValueError("wire type %d" % wire)
        yield number, wire, value


def signed64(v):
    return v - (1 << 64) if v >= 1 << 63 else v


def repeated_varints(wire, value):
    if wire == 0:
        return [value]
    out, at = [], 0
    while at < len(value):
        v, at = varint(value, at)
        out.append(v)
    return out


def repeated_floats(wire, value):
    return list(struct.unpack("<%df" % (len(value) // 4), value))


def vec3(buf):
    v = [0.0, 0.0, 0.0]
    for n, _, x in fields(buf):
        v[n - 1] = struct.unpack("<d", x)[0]
    return v


FIELD_NAMES = ["displacement", "strain", "stiffness", "mass"]


def surface_fields(buf):
    out = {name: [] for name in FIELD_NAMES}
    for n, wire, value in fields(buf):
        if 1 <= n <= 4:
            out[FIELD_NAMES[n - 1]] += repeated_floats(wire, value)
    return out


class Decoder:
    def __init__(self):
        self.step = None

    def apply(self, frame):
        body = {}
        step, time, skipped = 0, 0.0, 0
        for n, wire, value in fields(frame):
            if n == 1:
                step = signed64(value)
            elif n == 2:
                time = struct.unpack("<d", value)[0]
            elif n in (3, 4):
                body = {"key": n == 3, "bytes": value}
            elif n == 5:
                skipped = signed64(value)
        if body["key"]:
            self.keyframe(body["bytes"])
        else:
            self.delta(body["bytes"])
        self.step, self.time, self.skipped = step, time, skipped
        return body["key"]

    def keyframe(self, buf):
        self.topology_version, n, self.quads, codes = 0, 0, [], b""
        self.fields = {name: [] for name in FIELD_NAMES}
        for f, wire, value in fields(buf):
            if f == 1:
                self.topology_version = signed64(value)
            elif f == 2:
                n = value
            elif f == 3:
                self.quads += repeated_varints(wire, value)
            elif f == 4:
                for g, _, v in fields(value):
                    if g == 1:
                        self.origin = vec3(v)
                    else:
                        self.grid_step = vec3(v)
            elif f == 5:
                self.error_bound = vec3(value)
            elif f == 6:
                codes = value
            elif f == 7:
                self.fields = surface_fields(value)
        assert len(codes) == 6 * n, "codes %d bytes for %d vertices" % (len(codes), n)
        self.codes = list(struct.unpack("<%dH" % (3 * n), codes))
        self.rice, self.moved = False, 0

    def delta(self, buf):
        base, runs, bits, packed, moved, rice_k = 0, [], 0, b"", 0, []
        changes = {name: [] for name in FIELD_NAMES}
        for f, wire, value in fields(buf):
            if f == 1:
                base = signed64(value)
            elif f == 2:
                runs += repeated_varints(wire, value)
            elif f == 3:
                bits = value
            elif f == 4:
                packed = value
            elif f == 6:
                changes = surface_fields(value)
            elif f == 7:
                moved = value
            elif f == 8:
                rice_k += repeated_varints(wire, value)
        assert base == self.step, "base_step %d, last step %d" % (base, self.step)
        listed, at = [], 0
        for i, r in enumerate(runs):
            if i % 2 == 1:
                listed += range(at, at + r)
            at += r
        assert len(listed) == moved
        bit = [0]

        def read(count):
            v = 0
            for b in range(count):
                byte = packed[bit[0] >> 3]
                v |= ((byte >> (bit[0] & 7)) & 1) << b
                bit[0] += 1
            return v

        for v in listed:
            for a in range(3):
                if rice_k:
                    k, ones = rice_k[a], 0
                    while ones < 16 and read(1) == 1:
                        ones += 1
                    z = read(17) if ones == 16 else (ones << k) | read(k)
                else:
                    z = read(bits)
                d = -(z >> 1) - 1 if z & 1 else z >> 1
                self.codes[3 * v + a] += d
                assert 0 <= self.codes[3 * v + a] <= 65535
        assert len(packed) == (bit[0] + 7) // 8, "packed has %d bytes, used %d bits" % (
            len(packed), bit[0])
        for name in FIELD_NAMES:
            for i, x in enumerate(changes[name]):
                self.fields[name][listed[i]] = x
        self.rice, self.moved = bool(rice_k), moved

    def positions(self):
        return [self.origin[i % 3] + c * self.grid_step[i % 3] for i, c in enumerate(self.codes)]


def main():
    directory = sys.argv[1] if len(sys.argv) > 1 else os.environ["DYNSOLID_VECTORS_DIR"]
    with open(os.path.join(directory, "frames.bin"), "rb") as f:
        data = f.read()
    with open(os.path.join(directory, "expected.json")) as f:
        expected = json.load(f)
    frames, at = [], 0
    while at < len(data):
        (size,) = struct.unpack_from("<I", data, at)
        frames.append(data[at + 4:at + 4 + size])
        at += 4 + size
    assert at == len(data), "frames.bin ends inside a frame"
    assert len(frames) == len(expected), "%d frames, %d expected" % (len(frames), len(expected))
    d = Decoder()
    for i, (frame, want) in enumerate(zip(frames, expected)):
        where = "frame %d (%s)" % (i, want["kind"])
        key = d.apply(frame)
        got = {
            "step": d.step, "time": d.time, "keyframe": key, "skipped": d.skipped,
            "topology_version": d.topology_version, "vertex_count": len(d.codes) // 3,
            "quads": d.quads, "positions": d.positions(), "error_bound": d.error_bound,
            "fields": d.fields, "rice": d.rice, "moved": d.moved,
        }
        for name, value in got.items():
            assert value == want[name], "%s: %s differs" % (where, name)
        bound = want["error_bound"]
        for j, (p, t) in enumerate(zip(got["positions"], want["true_positions"])):
            assert abs(p - t) <= bound[j % 3] * (1 + 1e-9), "%s: coordinate %d" % (where, j)
    kinds = sorted({w["kind"] for w in expected})
    print("%d frames decode as expected.json says (%s)" % (len(frames), ", ".join(kinds)))


if __name__ == "__main__":
    main()
