#!/usr/bin/env python3
"""Writes the seed corpus of tests/fuzz/corpus/ (checked in; rerun after
changing a seed). Seeds are the exact byte examples of docs/protocol.md and
the specification tests, laid out as each fuzz target reads its input."""

import os
import shutil
import struct
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "corpus")


def h(text):
    return bytes.fromhex(text.replace("\n", " "))


def write(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def routing_wire():
    t = "routing_wire"
    write(t, "data", h("10 4E 00 42 10 11 0E 01"))
    write(t, "data-payload", h("10 4E 00 42 10 11 0E 01 DE AD BE EF"))
    write(t, "data-flood", h("10 4E 00 FF FF 20 18 01 04 03 02 01"))
    write(t, "hello", h("11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03"))
    write(t, "update", h("""12 42 00 01 02 03 04 05 06 07 08 01
        4E 00 02 01 08 00 00 00 01 05 1E 00 00 00 02 06 02
        FF FF FF FF 04 03 02 01 00"""))
    write(t, "seqno-request", h("13 42 00 4E 00 FE FF 07"))
    write(t, "claim", h("14 34 12 11 11 11 11 11 11 11 11 01 02 03 04 05 06 07 08 20"))
    write(t, "conflict", h("""15 34 12 A1 00 00 00 00 00 00 00 B2 00 00 00 00
        00 00 00 C3 00 00 00 00 00 00 00 09"""))
    # Authenticated (docs/protocol.md, "Authentication"): the data header
    # with flag bit 5, and a hello with a trailer (key id 1, index
    # 0x01020304, counter 1, an 8-byte tag that no key makes).
    write(t, "data-auth", h("10 4E 00 42 10 11 2E 01 DE AD BE EF"))
    write(t, "hello-trailer", h("""11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03
        01 04 03 02 01 01 00 00 00 00 00 00 00 11 22 33 44 55 66 77 88"""))
    # RFC 8967's challenge (docs/protocol.md, "Authentication"): request
    # and reply with nonce 01..08, and a request with a trailer (index
    # 0x0A0B0C0D, counter 7, a tag that no key makes).
    write(t, "challenge-request", h("16 01 02 03 04 05 06 07 08"))
    write(t, "challenge-reply", h("17 01 02 03 04 05 06 07 08"))
    write(t, "challenge-request-trailer", h("""16 01 02 03 04 05 06 07 08
        01 0D 0C 0B 0A 07 00 00 00 00 00 00 00 11 22 33 44 55 66 77 88"""))


def auth():
    # settings (bit 0: 16-byte tags; bits 3..1: link code), mutation count,
    # mutations (position u16, kind, value), then the packet body.
    t = "auth"
    hello = h("11 4E 00 01 02 03 04 05 06 07 08 CD AB E8 03")
    write(t, "hello-unchanged", bytes([0x08, 0]) + hello)
    write(t, "hello-flip", bytes([0x08, 1, 3, 0, 0, 0x10]) + hello)
    write(t, "hello-tag16-cut", bytes([0x09, 1, 0, 0, 2, 0]) + hello)
    write(t, "data-append", bytes([0x0A, 1, 0, 0, 3, 7])
          + h("10 4E 00 42 10 11 0E 01 DE AD BE EF"))
    write(t, "empty-body", bytes([0x08, 2, 0, 0, 1, 0, 9, 0, 0, 1]))
    # A challenge request; one mutation alters the reply's nonce (byte 3).
    write(t, "challenge-request", bytes([0x0C, 1, 3, 0, 1, 0x40])
          + h("16 01 02 03 04 05 06 07 08"))


def asl_wire():
    t = "asl_wire"
    write(t, "query-type", h("01 01 04 03 02 01 01 03 63 61 6D"))
    write(t, "query-any", h("01 01 05 00 00 00 02 00"))
    write(t, "answer", h("01 02 0A 00 00 00 02 11 00 00 00 01 61 01 74 22 00 00 00 00 00"))
    write(t, "request", h("01 03 01 02 03 04 05 06 07 08 2A 00 00 00 DE AD"))
    write(t, "request-oneway", h("01 03 00 00 00 00 00 00 00 00 2A 00 00 00"))
    write(t, "response-ok", h("01 04 01 02 03 04 05 06 07 08 01 BE EF"))
    write(t, "response-error", h("""01 04 01 02 03 04 05 06 07 08 00
        F2 AD B6 0F 00 00 00 00 10 04 67 6F 6E 65"""))
    write(t, "watch", h("01 05 2A 00 00 00"))
    write(t, "unwatch", h("01 06 2A 00 00 00"))
    write(t, "down", h("01 07 2A 00 00 00 F2 AD B6 0F 00 00 00 00 10 00"))
    write(t, "withdraw", h("01 08 2A 00 00 00 03 63 61 6D"))
    write(t, "subscribe", h("01 09 04 70 6F 73 65 E8 03 00 00"))
    write(t, "unsubscribe", h("01 0A 04 70 6F 73 65"))
    write(t, "publish", h("01 0B 04 70 6F 73 65 07 00 00 00 01 02"))
    write(t, "advertise", h("01 0C 04 70 6F 73 65"))
    write(t, "reliable-request", h("01 0D 01 02 03 04 05 06 07 08 2A 00 00 00 00 DE AD"))
    write(t, "reliable-oneway", h("01 0D 05 00 00 00 00 00 00 00 2A 00 00 00 01"))
    write(t, "ack", h("01 0E 01 02 03 04 05 06 07 08"))


def marshal():
    t = "marshal"

    def elem(name, value):
        return bytes([len(name)]) + name.encode() + value

    def payload(*elems):
        return bytes([1, len(elems)]) + b"".join(elems)

    # The golden payload of tests/actors/marshal_test.cpp.
    write(t, "golden", h("""01 02 04 40 75 31 36 02 01
        12 68 65 72 6D 3A 3A 77 72 69 74 65 5F 70 61 63 6B 65 74
        07 00 00 00 00 00 00 00 01 02 DE AD"""))
    write(t, "empty", h("01 00"))
    write(t, "integers", payload(elem("@i8", b"\xff"), elem("@i16", b"\xfe\xff"),
                                 elem("@i32", b"\x2a\x00\x00\x00"),
                                 elem("@u64", b"\x01" * 8)))
    write(t, "strings", payload(elem("@str", b"\x03abc"),
                                elem("@u16str", b"\x04x\x00y\x00"),
                                elem("@u32str", b"\x04z\x00\x00\x00")))
    write(t, "set-bool-float", payload(elem("@strset", b"\x02\x01a\x02bc"),
                                       elem("bool", b"\x01"),
                                       elem("float", struct.pack("<f", 1.5)),
                                       elem("double", struct.pack("<d", -2.25))))
    write(t, "atom-timespan", payload(elem("@atom", h("F2 AD B6 0F 00 00 00 00")),
                                      elem("@timespan", struct.pack("<q", 5000)),
                                      elem("@timestamp", struct.pack("<q", 7))))
    # Regression: a caf::duration with time unit 0x10000000 crashed printing.
    write(t, "regression-duration-unit",
          payload(elem("@duration", struct.pack("<IQ", 0x10000000, 1))))


def serial_framing():
    t = "serial_framing"
    # MTU byte (MTU = 1 + x % 255), options (bit 0 escaped, bits 1.. chunk).
    write(t, "hi", bytes([31, 0x02]) + h("00 01 05 48 69 B5 76 00"))
    write(t, "escaped", bytes([31, 0x03]) + h("01 06 7D 31 7D 33 7D 5D 09 89 00"))
    write(t, "garbage-then-frame", bytes([7, 0x08]) + h("11 22 00 00 33 01 05 48 69 B5 76 00"))
    write(t, "cobs-long", bytes([254, 0x00]) + bytes(range(1, 256)))


def can_id():
    t = "can_id"

    def seed(flags, can_id, length, other, prio, dst, src, size):
        return (bytes([flags]) + struct.pack("<I", can_id) + bytes([length])
                + struct.pack("<I", other) + bytes([prio, dst, src, size]))

    eff = 0x80000000
    # Priority 2, 0x34 -> 0x12, 3 bytes of padding (docs/protocol.md).
    write(t, "fd-padded", seed(2, eff | 0x0848D253, 12, eff | 0x0848D250, 2, 0x12, 0x34, 9))
    write(t, "classic", seed(0, eff | 0x0848D250, 8, 0x123, 0, 0xFF, 1, 8))
    write(t, "std11", seed(1, 0x2F1, 3, eff | 0x1FFFFFFF, 7, 15, 14, 3))


def emu_wire():
    t = "emu_wire"
    now = 10_000_000_000

    def prefix(mtu, opts=0):
        return struct.pack("<H", mtu) + struct.pack("<Q", now << 1) + bytes([opts])

    emu = struct.pack("<HBBHHq", 0x4D45, 1, 1, 2, 0, now + 1000)
    write(t, "emu", prefix(1500) + emu + b"hello")
    can_frame = struct.pack("<IBBBB", 0x80000000 | 0x0848D250, 3, 0, 0, 0) + b"abc" + bytes(5)
    can = struct.pack("<HBBIq", 0x4843, 1, 0, 0, now)
    write(t, "can", prefix(8) + can + can_frame)
    fd_frame = struct.pack("<IBBBB", 0x80000000 | 0x0848D253, 12, 0x04, 0, 0) + bytes(64)
    write(t, "canfd", prefix(64) + can + fd_frame)


def fragmentation():
    t = "fragmentation"
    mtu8 = struct.pack("<H", 0)      # MTU 8
    mtu64 = struct.pack("<H", 56)    # MTU 64: wide sequence numbers
    # The worked example of docs/protocol.md, from sender 1, then an honest
    # packet of 20 bytes interleaved.
    frames = [h("40 14 00 01 02 03 04 05"), h("81 06 07 08 09 0A 0B 0C"),
              h("82 0D 0E 0F 10 11 12 13"), h("83 A4 FF DD 3B")]
    s = mtu8 + bytes([1, 20, 0, 0])      # honest packet: 20 pseudo-random bytes
    for f in frames:
        s += bytes([0, 1, len(f)]) + f   # frame from sender 1, one honest step
    write(t, "worked-example", s)
    # Honest packets only: swaps and repeats, narrow and wide.
    write(t, "honest-swaps", mtu8 + bytes([1, 200, 0, 3, 40, 0x07, 2, 0x10, 0x00]))
    write(t, "honest-wide", mtu64 + bytes([1, 0x00, 0x04, 0, 3, 80, 0x03]))
    write(t, "honest-content", mtu8 + bytes([1, 100, 0, 1]) + bytes(range(1, 17))
          + bytes([3, 100, 0x02]))
    # Two lanes of the honest sender, both packets with tag 0: a bulk packet
    # of 256 bytes in lane 0, a control packet of 24 bytes in lane 1 whose
    # frames overtake it, first all at once, then split around bulk frames
    # (the CAN controller's order, docs/reliability.md "Overload").
    write(t, "honest-two-lanes", mtu8 + bytes([1, 0x00, 0x01, 0x00, 1, 24, 0, 0x80,
                                               3, 10, 0x00, 3, 5, 0x08,
                                               1, 24, 0, 0x80,
                                               3, 2, 0x08, 3, 6, 0x00, 3, 3, 0x08,
                                               3, 40, 0x00]))
    # Regression: the first fuzz finding (fixed in 5e0fb4b): any fragmented
    # packet made the fragmenter compute crc + (offset - size) out of range.
    write(t, "regression-crc-pointer", h("38 00 01 50"))
    # A single frame, a bad header, an orphan, then time passes.
    write(t, "misc", mtu8 + bytes([0, 2, 3]) + h("00 AA BB") + bytes([0, 3, 2]) + h("4F 01")
          + bytes([0, 4, 3]) + h("85 01 02") + bytes([2, 0xD0, 0x07]))


def alias_bomb():
    """Regression: aliases of one large string in channel options expanded
    to gigabytes (std::bad_alloc, exit 134); here 1 KiB repeated 10^4
    times through nested lists, within libFuzzer's 4096-byte max_len."""
    text = (b"module: {name: m}\nchannels:\n  - name: a\n    kind: inproc\n"
            b"    interface: seg\n    big: &s " + b"x" * 1024 + b"\n")
    prev = b"s"
    for i in range(1, 5):
        cur = b"l%d" % i
        text += b"    " + cur + b": &" + cur + b" [" + b", ".join(
            [b"*" + prev] * 10) + b"]\n"
        prev = cur
    return text


def alias_laughs():
    """Ten levels of ten aliases: 10^10 nodes from a few hundred bytes."""
    text = b"module: {name: m}\nx0: &x0 [" + b", ".join([b"lol"] * 10) + b"]\n"
    for i in range(1, 10):
        text += b"x%d: &x%d [" % (i, i) + b", ".join(
            [b"*x%d" % (i - 1)] * 10) + b"]\n"
    return text


def config():
    t = "config"
    src = os.path.join(HERE, "..", "..", "apps", "hermd", "examples")
    for name in sorted(os.listdir(src)):
        if name.endswith(".yaml"):
            shutil.copy(os.path.join(src, name), os.path.join(CORPUS, t, name))
    write(t, "minimal.yaml", b"module:\n  name: m\n")
    # Regression: a lone "," made yaml-cpp's LoadAll loop for ever.
    write(t, "regression-loadall-comma", b",")
    write(t, "regression-alias-bomb", alias_bomb())
    write(t, "regression-alias-laughs", alias_laughs())
    write(t, "full.yaml", b"""module:
  name: alpha
  id: 0x30
  hello_interval_ms: 250
  hello_loss: 1.5
  update_every: 4
  hold_factor: 3
  announce_every: 10
log: {level: debug, format: json}
scheduler: {policy: stealing, threads: 2}
control: {socket: off}
apps:
  tick_ms: 50
  request_timeout_ms: 5000
  unreachable_grace_ms: 0
  max_pending: 10
channels:
  - {name: eth0, kind: udp, interface: "127.0.0.1:0", peers: [a, b], mtu: 1472, profile: ethernet}
  - name: can0
    kind: can
    interface: emu:/tmp/bus
    node: 3
    delay_coef: 0.5
    bandwidth: 1000000
apos:
  - name: sonar
    kind: srf04_batcher
    type: herm.sonar/1
    options: {batch: 10, target: [x, y]}
""")


def bundle():
    # First byte: max_packet = byte * 8 + 1; then the frame.
    write("bundle", "worked-example", h("20 01 02") + b"hi" + h("03") + b"abc")
    write("bundle", "three", h("FF 01 01 41 81 01") + b"B" * 129 + h("01 43"))
    write("bundle", "one-packet", h("20 01 02") + b"hi")


def srf04():
    write("srf04", "reading", h("07 00 E8 06 45 28 00 00"))
    write("srf04", "short", h("07 00 E8"))


def main():
    if os.path.isdir(CORPUS):
        shutil.rmtree(CORPUS)
    os.makedirs(os.path.join(CORPUS, "config"))
    for gen in (routing_wire, auth, asl_wire, marshal, serial_framing, can_id,
                emu_wire, fragmentation, bundle, config, srf04):
        gen()
    return 0


if __name__ == "__main__":
    sys.exit(main())
