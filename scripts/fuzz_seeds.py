#!/usr/bin/env python3
"""Write the fuzz seed corpus: small valid and nearly-valid inputs for each target.

Usage: python3 scripts/fuzz_seeds.py   (writes fuzz/seeds/<target>/seed-*; deterministic)

The signal is a short gear-mesh-like vibration (mesh line, a harmonic, shaft sidebands,
seeded noise): 256 samples at 25.6 kHz (10 ms), so each seed stays at a few KB. The WAV
layouts follow `gearwear::record::encode_wav` (16-bit PCM, 32-bit float) plus the other
encodings `parse_wav` accepts (8/24/32-bit PCM, 64-bit float, WAVE_FORMAT_EXTENSIBLE,
stereo, an extra odd-sized chunk before `data`). Multichannel CSV and JSON bodies exercise
`parse_record_channels` and the JSON `channels` form.
"""
import gzip
import math
import os
import random
import struct

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
CORPUS = os.path.join(ROOT, "fuzz", "seeds")
FS = 25600
N = 256


def signal(n=N, seed=1):
    rnd = random.Random(seed)
    f1, shaft = 870.0, 30.0
    out = []
    for i in range(n):
        t = i / FS
        v = 0.5 * math.sin(2 * math.pi * f1 * t)
        v += 0.15 * math.sin(2 * math.pi * 2 * f1 * t + 0.3)
        v += 0.05 * math.sin(2 * math.pi * (f1 + shaft) * t)
        v += 0.05 * math.sin(2 * math.pi * (f1 - shaft) * t)
        v += 0.02 * rnd.gauss(0.0, 1.0)
        out.append(v)
    return out


def write(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, "seed-" + name), "wb") as f:
        f.write(data)


def wav(samples, tag=1, bits=16, channels=1, rate=FS, extensible=False, extra_chunk=False):
    bpb = (bits + 7) // 8
    frames = []
    for s in samples:
        for c in range(channels):
            v = s if c == 0 else -s
            if tag == 3 and bits == 32:
                frames.append(struct.pack("<f", v))
            elif tag == 3 and bits == 64:
                frames.append(struct.pack("<d", v))
            elif bits == 8:
                frames.append(struct.pack("<B", max(0, min(255, int(round(v * 127 + 128))))))
            elif bits == 16:
                frames.append(struct.pack("<h", int(round(max(-1, min(1, v)) * 32767))))
            elif bits == 24:
                x = int(round(max(-1, min(1, v)) * 8388607))
                frames.append(struct.pack("<i", x)[:3])
            else:
                frames.append(struct.pack("<i", int(round(max(-1, min(1, v)) * 2147483647))))
    data = b"".join(frames)
    block = bpb * channels
    if extensible:
        fmt = struct.pack("<HHIIHH", 0xFFFE, channels, rate, rate * block, block, bits)
        # cbSize, valid bits, channel mask, sub-format GUID (starts with the real tag)
        fmt += struct.pack("<HHI", 22, bits, 0) + struct.pack("<H", tag) + bytes(14)
    else:
        fmt = struct.pack("<HHIIHH", tag, channels, rate, rate * block, block, bits)
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt
    if extra_chunk:
        body = b"gearwear"[:7]  # odd size: padded to even
        chunks += b"LIST" + struct.pack("<I", len(body)) + body + b"\0"
    chunks += b"data" + struct.pack("<I", len(data)) + data
    return b"RIFF" + struct.pack("<I", 4 + len(chunks)) + b"WAVE" + chunks


def main():
    x = signal()
    short = x[:64]

    # JSON bodies (POST /v1/machines/{id}/records, application/json)
    nums = ",".join("%.6g" % v for v in x)
    write("json_body", "full.json",
          '{"sample_rate_hz": 25600, "samples": [%s], "shaft_hz": 30.0, '
          '"recorded_at": "2026-11-22T08:30:00Z", "sensor": "gearbox-1/acc-x"}' % nums)
    write("json_body", "minimal.json",
          '{"sample_rate_hz":25600,"samples":[%s]}' % ",".join("%.4g" % v for v in short))
    write("json_body", "zero-rate.json", '{"sample_rate_hz":0,"samples":[0.1,0.2]}')
    write("json_body", "nan.json", '{"sample_rate_hz":25600,"samples":[1,NaN,2]}')
    write("json_body", "unknown-field.json", '{"sample_rate_hz":1,"samples":[1],"x":1}')
    write("json_body", "bad-time.json",
          '{"sample_rate_hz":8000,"samples":[1e-3,-2.5E+2],"recorded_at":"2026-02-30T25:00:00+01:00"}')
    write("json_body", "empty.json", '{"sample_rate_hz":8000,"samples":[]}')
    y = signal(64, seed=2)
    write("json_body", "channels.json",
          '{"sample_rate_hz": 25600, "channels": {"a1": [%s], "a2": [%s]}, "shaft_hz": 30}'
          % (",".join("%.4g" % v for v in short), ",".join("%.4g" % v for v in y)))
    write("json_body", "channels-and-samples.json",
          '{"sample_rate_hz":1,"samples":[1,2],"channels":{"a1":[1,2],"a1":[3]}}')

    # CSV (text/csv and .csv files)
    write("csv", "one-column.csv", "".join("%.9e\n" % v for v in x))
    write("csv", "time-value.csv",
          "time,acc\n" + "".join("%.8f,%.6f\n" % (i / FS, v) for i, v in enumerate(short)))
    write("csv", "columns-comments.csv",
          "# rig A, run 7\n\ufeffvalue;time_s;other\n" +
          "".join("%.5f;%.8f;%d\r\n" % (v, i / FS, i) for i, v in enumerate(short)) +
          "# end\n")
    write("csv", "tabs.csv", "".join("%.8f\t%.5f\n" % (i / FS, v) for i, v in enumerate(short)))
    write("csv", "spaces-quotes.csv",
          '"t"  "value"\n' + "".join("%.8f   %.5f\n" % (i / FS, v) for i, v in enumerate(short[:16])))
    write("csv", "nonuniform.csv", "t,v\n0,1\n0.1,2\n0.5,3\n")
    write("csv", "nan.csv", "1\n2\nnan\ninf\n")
    write("csv", "ragged.csv", "1,2\n3\n")
    # Several channels, as the SpectraQuest records (a1..a4), with and without a time column.
    chans = [signal(64, seed=s) for s in (3, 4, 5, 6)]
    write("csv", "four-channels.csv",
          "a1,a2,a3,a4\n" + "".join("%.6f,%.6f,%.6f,%.6f\n" % r for r in zip(*chans)))
    write("csv", "time-channels.csv",
          "time,a1,a2\n" + "".join("%.8f,%.6f,%.6f\n" % (i / FS, a, b)
                                    for i, (a, b) in enumerate(zip(chans[0], chans[1]))))

    # gzip (.csv.gz files read by the CLI)
    write("csv_gz", "one-column.csv.gz", gzip.compress("".join("%.9e\n" % v for v in x).encode(), 9, mtime=0))
    write("csv_gz", "time-value.csv.gz",
          gzip.compress(("time,acc\n" + "".join("%.8f,%.6f\n" % (i / FS, v) for i, v in enumerate(short))).encode(), 6, mtime=0))
    two = gzip.compress(b"1\n2\n", mtime=0) + gzip.compress(b"3\n4\n", mtime=0)
    write("csv_gz", "two-members.csv.gz", two)
    write("csv_gz", "zeros.gz", gzip.compress(b"0\n" * 4000, 9, mtime=0))
    write("csv_gz", "truncated.gz", gzip.compress(b"1\n2\n3\n", mtime=0)[:-6])

    # raw little-endian f32
    write("f32_raw", "signal.f32", b"".join(struct.pack("<f", v) for v in x))
    write("f32_raw", "short.f32", b"".join(struct.pack("<f", v) for v in short[:8]))
    write("f32_raw", "odd-length.f32", b"".join(struct.pack("<f", v) for v in short[:8])[:-1])
    write("f32_raw", "inf.f32", struct.pack("<fff", 1.0, float("inf"), 2.0))

    # WAV
    write("wav", "pcm16.wav", wav(x))
    write("wav", "float32.wav", wav(x, tag=3, bits=32))
    write("wav", "pcm8.wav", wav(short, bits=8))
    write("wav", "pcm24-stereo.wav", wav(short, bits=24, channels=2))
    write("wav", "pcm32.wav", wav(short, bits=32))
    write("wav", "float64.wav", wav(short, tag=3, bits=64))
    write("wav", "extensible-float.wav", wav(short, tag=3, bits=32, extensible=True))
    write("wav", "list-chunk.wav", wav(short, extra_chunk=True))
    write("wav", "zero-rate.wav", wav(short[:8], rate=0))
    write("wav", "truncated.wav", wav(short)[:-3])

    # model configs
    for name in ("model_a.toml", "model_b.toml"):
        with open(os.path.join(ROOT, "configs", name), "rb") as f:
            write("model_config", name, f.read())


if __name__ == "__main__":
    main()
