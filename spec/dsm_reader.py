#!/usr/bin/python3
"""An independent reader of .dsm files, written from spec/dsm-format.md alone.

Standard library and NumPy only. It reads versions 1.0 and 1.1 (both tile
layouts), checks every CRC and the layout rules it needs to read safely, and
gives every pixel of every level as arrays. Maps whose tiles are zstd frames
(header codec 1) also need the module zstandard (Debian: python3-zstandard) or
zstd (python3-zstd); without either such a map is refused with a message.

    dsm_reader.py FILE...          print a canonical dump of every pixel
    dsm_reader.py --summary FILE   print the header and level table

The dump has one line per non-empty pixel:
    L x y c=C layers=S1,S2 z=HEX... v=HEX... n=COUNT...
with depths and values as float32 bit patterns in hex, so that two readers
that agree bit for bit print the same text (tests/support/dump_map.cpp prints
the same from libdsm's reader).
"""

import math
import struct
import sys
import zlib

import numpy as np

MAGIC = b"\x89DSM\r\n\x1a\n"
HAS_COUNTS, HAS_LAYERS, CODED_TILES, PREDICTED_DEPTHS = 1, 2, 4, 8
CODEC_ZLIB, CODEC_ZSTD = 0, 1
PIXEL_RGB = 1


class FormatError(Exception):
    pass


def crc32(data):
    return zlib.crc32(data) & 0xFFFFFFFF


class Header:
    pass


def read_header(data):
    if data[:8] != MAGIC:
        raise FormatError("bad magic")
    h = Header()
    h.major, h.minor, h.header_size = struct.unpack_from("<HHI", data, 8)
    if h.major != 1:
        raise FormatError("major version %d" % h.major)
    if h.header_size < 272 or h.header_size > len(data) or (h.minor >= 1 and h.header_size < 296):
        raise FormatError("header size %d" % h.header_size)
    head = bytearray(data[: h.header_size])
    stored_crc = struct.unpack_from("<I", head, 228)[0]
    head[228:232] = b"\0\0\0\0"
    if crc32(bytes(head)) != stored_crc:
        raise FormatError("header CRC")
    (h.required, h.optional, h.width, h.height, h.tile_size) = struct.unpack_from("<5I", data, 16)
    h.channels, h.max_layers, h.filter, h.projection = struct.unpack_from("<4B", data, 36)
    h.filter_width = struct.unpack_from("<d", data, 40)[0]
    h.world_to_light = struct.unpack_from("<16d", data, 48)
    h.screen_window = struct.unpack_from("<4d", data, 176)
    h.near_plane = struct.unpack_from("<d", data, 208)[0]
    (h.level_count, h.level_entry_size, h.tile_entry_size) = struct.unpack_from("<3I", data, 216)
    (h.level_table_offset, h.metadata_offset, h.metadata_size) = struct.unpack_from("<3Q", data, 232)
    h.level_table_crc, h.metadata_crc = struct.unpack_from("<2I", data, 256)
    h.file_size = struct.unpack_from("<Q", data, 264)[0]
    h.codec, h.codec_level = 0, None
    h.area_light_radius = h.area_light_plane_depth = 0.0
    if h.header_size >= 296:
        h.codec, h.codec_level = struct.unpack_from("<2B", data, 272)
        h.area_light_radius, h.area_light_plane_depth = struct.unpack_from("<2d", data, 280)
    if h.file_size != len(data):
        raise FormatError("file size %d, header says %d" % (len(data), h.file_size))
    if h.required & ~(HAS_COUNTS | HAS_LAYERS | CODED_TILES | PREDICTED_DEPTHS):
        raise FormatError("unknown required flags 0x%x" % h.required)
    if (h.required & CODED_TILES) and h.minor < 1:
        raise FormatError("coded tiles in a 1.0 file")
    if (h.required & PREDICTED_DEPTHS) and not (h.required & CODED_TILES):
        raise FormatError("predicted depths without coded tiles")
    if h.codec not in (CODEC_ZLIB, CODEC_ZSTD):
        raise FormatError("unknown codec %d" % h.codec)
    if h.codec == CODEC_ZSTD and zstd_decompress is None:
        raise FormatError("the tiles are zstd frames: this reader needs the Python module zstandard "
                          "(Debian: python3-zstandard) or zstd (python3-zstd)")
    if h.channels not in (1, 3) or h.max_layers < 1:
        raise FormatError("channels or layers")
    if bool(h.required & HAS_LAYERS) != (h.max_layers > 1):
        raise FormatError("layer flag")
    if h.level_entry_size < (80 if h.minor >= 1 else 72) or h.tile_entry_size < 40:
        raise FormatError("entry sizes")
    return h


def section(data, offset, size, crc, what):
    if offset > len(data) or size > len(data) - offset:
        raise FormatError("%s does not fit" % what)
    part = data[offset : offset + size]
    if crc32(part) != crc:
        raise FormatError("%s CRC" % what)
    return part


class Level:
    pass


def read_levels(data, h):
    table = section(data, h.level_table_offset, h.level_count * h.level_entry_size, h.level_table_crc, "level table")
    levels = []
    w, hh = h.width, h.height
    for l in range(h.level_count):
        e = l * h.level_entry_size
        L = Level()
        (L.width, L.height, L.tiles_x, L.tiles_y) = struct.unpack_from("<4I", table, e)
        L.tolerance, L.error_bound = struct.unpack_from("<2d", table, e + 16)
        (L.directory_offset, L.vertex_count, L.non_empty, L.stored_bytes) = struct.unpack_from("<4Q", table, e + 32)
        L.directory_crc = struct.unpack_from("<I", table, e + 64)[0]
        L.value_step = struct.unpack_from("<d", table, e + 72)[0] if h.level_entry_size >= 80 else 0.0
        if (L.width, L.height) != (w, hh):
            raise FormatError("level %d size" % l)
        ts = h.tile_size
        if (L.tiles_x, L.tiles_y) != (-(-w // ts), -(-hh // ts)):
            raise FormatError("level %d tile counts" % l)
        if L.value_step != 0.0:
            mantissa, exponent = np_frexp(L.value_step)
            if mantissa != 0.5 or not (-24 <= exponent - 1 <= -1) or not (h.required & CODED_TILES):
                raise FormatError("level %d value step %r" % (l, L.value_step))
        count = L.tiles_x * L.tiles_y
        directory = section(data, L.directory_offset, count * h.tile_entry_size, L.directory_crc, "directory")
        L.tiles = []
        for t in range(count):
            L.tiles.append(read_directory_entry(directory, t * h.tile_entry_size, L, t, h, len(data), l))
        if (sum(t[4] for t in L.tiles), sum(t[7] for t in L.tiles), sum(t[1] for t in L.tiles)) != (
                L.vertex_count, L.non_empty, L.stored_bytes):
            raise FormatError("level %d: level totals do not match its tile directory" % l)
        levels.append(L)
        w, hh = -(-w // 2), -(-hh // 2)
    return levels


def np_frexp(x):
    m, e = np.frexp(x)
    return float(m), int(e)


def zstd_module():
    """A function that decompresses one zstd frame, or None without a module for it."""
    try:
        import zstandard
        return lambda frame, size: zstandard.ZstdDecompressor().decompress(frame, max_output_size=size)
    except ImportError:
        pass
    try:
        import zstd
        return lambda frame, size: zstd.decompress(frame)
    except ImportError:
        return None


zstd_decompress = zstd_module()


def inflate(data, tile, where, codec=CODEC_ZLIB):
    offset, stored, raw, crc = tile[:4]
    part = section(data, offset, stored, crc, where)
    if stored == raw:
        return part
    if stored > raw:
        raise FormatError("%s: stored size above raw size" % where)
    try:
        out = zstd_decompress(part, raw) if codec == CODEC_ZSTD else zlib.decompress(part)
    except zlib.error:
        raise
    except Exception as e:  # the zstd modules' own errors
        raise FormatError("%s: zstd cannot decompress the tile: %s" % (where, e))
    if len(out) != raw:
        raise FormatError("%s: inflates to %d bytes, not %d" % (where, len(out), raw))
    return out


def read_varints(buf, pos, count):
    """count LEB128 values from buf[pos:]; returns (uint32 array, new pos)."""
    out = np.empty(count, dtype=np.uint32)
    end = len(buf)
    for i in range(count):
        value, shift = 0, 0
        while True:
            if pos >= end:
                raise FormatError("coded tile data ends early")
            b = buf[pos]
            pos += 1
            if shift == 28 and b > 0x0F:
                raise FormatError("varint beyond 32 bits")
            value |= (b & 0x7F) << shift
            if b < 0x80:
                break
            shift += 7
        out[i] = value
    return out, pos


def unzigzag(u):
    return (u >> 1) ^ (-(u & 1) & 0xFFFFFFFF)


def read_directory_entry(directory, d, L, t, h, file_size, l):
    """One tile's directory entry, checked by section 10's rules:
    (offset, stored, raw, crc, vertices, min_z, max_z, non_empty)."""
    offset, stored, raw, crc, vertices, min_bits, max_bits, non_empty = struct.unpack_from("<QIIIIIII", directory, d)
    min_z, max_z = struct.unpack_from("<2f", directory, d + 24)
    tx, ty = t % L.tiles_x, t // L.tiles_x
    where = "level %d tile %d,%d" % (l, tx, ty)
    pixels = min(h.tile_size, L.width - tx * h.tile_size) * min(h.tile_size, L.height - ty * h.tile_size)
    if stored == 0:
        if (offset, raw, crc, vertices, min_bits, max_bits, non_empty) != (0, 0, 0, 0, 0, 0, 0):
            raise FormatError("%s: empty tile with non-zero fields" % where)
        return (offset, stored, raw, crc, vertices, min_z, max_z, non_empty)
    if offset < h.header_size or offset + stored > file_size:
        raise FormatError("%s: data does not fit in the file" % where)
    if raw < stored:
        raise FormatError("%s: stored size above raw size" % where)
    if vertices == 0 or not 0 < non_empty <= pixels:
        raise FormatError("%s: vertex or non-empty pixel count" % where)
    if not (math.isfinite(min_z) and math.isfinite(max_z) and 0.0 <= min_z <= max_z):
        raise FormatError("%s: depth range" % where)
    return (offset, stored, raw, crc, vertices, min_z, max_z, non_empty)


def check_pixels(decoded, h, tile, where):
    """Section 10's rules for the pixels of one decoded tile, and the
    directory's depth range and non-empty count against them."""
    min_z, max_z, non_empty = tile[5], tile[6], tile[7]
    seen_min, seen_max, seen = math.inf, -math.inf, 0
    for p, (c, starts, z_bits, v_bits, counts) in enumerate(decoded):
        n = len(z_bits)
        if c > h.channels:
            raise FormatError("%s pixel %d: RGB pixel in a monochrome map" % (where, p))
        if len(starts) + 1 > h.max_layers or (len(starts) > 0 and len(starts) + 1 > n):
            raise FormatError("%s pixel %d: layer count" % (where, p))
        if len(starts) and (np.any(np.diff(starts.astype(np.int64)) <= 0) or starts[0] == 0 or starts[-1] >= n):
            raise FormatError("%s pixel %d: layer starts" % (where, p))
        if n == 0:
            continue
        z = z_bits.view(np.float32)
        if not np.all(np.isfinite(z)) or np.any(z < 0) or np.any(np.diff(z) < 0):
            raise FormatError("%s pixel %d: depths not finite, negative or decreasing" % (where, p))
        v = v_bits.view(np.float32).reshape(n, c)
        if not np.all(np.isfinite(v)) or np.any(v < 0) or np.any(v > 1):
            raise FormatError("%s pixel %d: values outside [0, 1]" % (where, p))
        rises = np.diff(v, axis=0) > 0
        rises[np.asarray(starts, dtype=np.int64) - 1] = False  # a layer may start anywhere
        if np.any(rises):
            raise FormatError("%s pixel %d: values increasing within a layer" % (where, p))
        seen += 1
        seen_min, seen_max = min(seen_min, float(z[0])), max(seen_max, float(z[-1]))
    if seen != non_empty or np.float32(seen_min) != np.float32(min_z) or np.float32(seen_max) != np.float32(max_z):
        raise FormatError("%s: depth range or non-empty pixels differ from the directory's" % where)


def decode_plain(raw, pixels, h):
    table = ((pixels * 6) + 3) & ~3
    cumulative = np.frombuffer(raw, dtype="<u4", count=pixels, offset=0).astype(np.int64)
    n = np.diff(np.concatenate(([0], cumulative)))
    if np.any(np.diff(cumulative) < 0) or (pixels and cumulative[0] < 0):
        raise FormatError("cumulative vertex counts decrease")
    flags = raw[4 * pixels : 5 * pixels]
    layers = raw[5 * pixels : 6 * pixels]
    check_flags(flags)
    pos = table
    out = []
    for p in range(pixels):
        c = 3 if flags[p] & PIXEL_RGB else 1
        k = int(n[p])
        starts = np.frombuffer(raw, "<u4", layers[p] - 1, pos).astype(np.uint32)
        pos += 4 * (layers[p] - 1)
        z = np.frombuffer(raw, "<u4", k, pos).copy()
        pos += 4 * k
        v = np.frombuffer(raw, "<u4", k * c, pos).copy()
        pos += 4 * k * c
        counts = None
        if h.required & HAS_COUNTS:
            counts = np.frombuffer(raw, "<u4", k, pos).copy()
            pos += 4 * k
        out.append((c, starts, z, v, counts))
    if pos != len(raw):
        raise FormatError("raw size differs from the pixel table")
    return out


def depth_run(first, steps):
    """Bit patterns: `first`, then each a step up from the one before."""
    z = np.empty(len(steps) + 1, np.uint64)
    z[0] = first
    z[1:] = first + np.cumsum(steps.astype(np.uint64))
    return (z & 0xFFFFFFFF).astype(np.uint32)


def decode_predicted_depths(raw, pos, n):
    """PREDICTED_DEPTHS: every pixel's ends, each from the previous non-empty
    pixel's, then the steps between a pixel's ends."""
    mask = 0xFFFFFFFF
    ends = []  # (first, last) bit patterns of each pixel, None when empty
    previous_first = previous_last = 0
    for k in (int(k) for k in n):
        if k == 0:
            ends.append(None)
            continue
        d, pos = read_varints(raw, pos, 2 if k > 1 else 1)
        first = (previous_first + unzigzag(int(d[0]))) & mask
        last = (previous_last + unzigzag(int(d[1]))) & mask if k > 1 else first
        ends.append((first, last))
        previous_first, previous_last = first, last
    depths = []
    for k, e in zip((int(k) for k in n), ends):
        if k == 0:
            depths.append(np.empty(0, np.uint32))
            continue
        steps, pos = read_varints(raw, pos, max(k - 2, 0))
        z = depth_run(e[0], steps)
        depths.append(np.append(z, np.uint32(e[1])) if k > 1 else z)
    return depths, pos


def decode_depths_by_pixel(raw, pos, n):
    """The first 1.1 coding (no PREDICTED_DEPTHS): pixel by pixel, the first
    depth from the previous non-empty pixel's first, then the steps."""
    depths = []
    previous_first = 0
    for k in (int(k) for k in n):
        if k == 0:
            depths.append(np.empty(0, np.uint32))
            continue
        d, pos = read_varints(raw, pos, k)
        first = (previous_first + unzigzag(int(d[0]))) & 0xFFFFFFFF
        previous_first = first
        depths.append(depth_run(first, d[1:]))
    return depths, pos


def check_flags(flags):
    if any(f & ~PIXEL_RGB for f in flags):
        raise FormatError("unknown pixel flags")


def decode_coded(raw, pixels, h, step):
    mask = 0xFFFFFFFF
    n, pos = read_varints(raw, 0, pixels)
    flags = raw[pos : pos + pixels]
    layers = raw[pos + pixels : pos + 2 * pixels]
    if len(flags) != pixels or len(layers) != pixels:
        raise FormatError("coded tile data ends early")
    pos += 2 * pixels
    check_flags(flags)
    channels = [3 if f & PIXEL_RGB else 1 for f in flags]
    starts = []
    for p in range(pixels):
        deltas, pos = read_varints(raw, pos, layers[p] - 1)
        starts.append(np.cumsum(deltas, dtype=np.uint64).astype(np.uint32))
    if h.required & PREDICTED_DEPTHS:
        depths, pos = decode_predicted_depths(raw, pos, n)
    else:
        depths, pos = decode_depths_by_pixel(raw, pos, n)
    one = 0x3F800000 if step == 0.0 else int(round(1.0 / step))
    values = []
    for p in range(pixels):
        k, c = int(n[p]), channels[p]
        d, pos = read_varints(raw, pos, k * c)
        d = d.reshape(k, c).astype(np.int64)
        keys = np.empty((k, c), np.int64)
        bounds = [0] + [int(s) for s in starts[p]] + [k]
        for a, b in zip(bounds[:-1], bounds[1:]):
            keys[a:b] = (one - np.cumsum(d[a:b], axis=0)) & mask
        keys = keys.reshape(-1).astype(np.uint32)
        if step == 0.0:
            values.append(keys)
        else:
            floats = keys.astype(np.float32) * np.float32(step)
            values.append(floats.view(np.uint32))
    counts = [None] * pixels
    if h.required & HAS_COUNTS:
        for p in range(pixels):
            counts[p], pos = read_varints(raw, pos, int(n[p]))
    if pos != len(raw):
        raise FormatError("coded tile data runs on after the counts")
    return [(channels[p], starts[p], depths[p], values[p], counts[p]) for p in range(pixels)]


def read_map(path):
    """(header, levels, pixels): pixels[level][(x, y)] = (channels, layer starts, z bits, v bits, counts)."""
    with open(path, "rb") as f:
        data = f.read()
    h = read_header(data)
    levels = read_levels(data, h)
    h.metadata = section(data, h.metadata_offset, h.metadata_size, h.metadata_crc, "metadata")
    pixels = []
    ts = h.tile_size
    for l, L in enumerate(levels):
        grid = {}
        for t, tile in enumerate(L.tiles):
            tx, ty = t % L.tiles_x, t // L.tiles_x
            w = min(ts, L.width - tx * ts)
            hh = min(ts, L.height - ty * ts)
            if tile[1] == 0:
                continue  # empty: every pixel fully lit
            where = "level %d tile %d,%d" % (l, tx, ty)
            raw = inflate(data, tile, where, h.codec)
            if h.required & CODED_TILES:
                decoded = decode_coded(raw, w * hh, h, L.value_step)
            else:
                decoded = decode_plain(raw, w * hh, h)
            check_pixels(decoded, h, tile, where)
            for p, pixel in enumerate(decoded):
                if len(pixel[2]):
                    grid[(tx * ts + p % w, ty * ts + p // w)] = pixel
        pixels.append(grid)
    return h, levels, pixels


def dump(path, out):
    h, levels, pixels = read_map(path)
    for l, grid in enumerate(pixels):
        for (x, y) in sorted(grid, key=lambda p: (p[1], p[0])):
            c, starts, z, v, counts = grid[(x, y)]
            line = "%d %d %d c=%d layers=%s z=%s v=%s" % (
                l, x, y, c, ",".join(str(int(s)) for s in starts),
                ",".join("%08x" % int(b) for b in z), ",".join("%08x" % int(b) for b in v))
            if h.required & HAS_COUNTS:
                line += " n=" + ",".join(str(int(k)) for k in counts)
            out.write(line + "\n")


def summary(path, out):
    h, levels, _ = read_map(path)
    out.write("version %d.%d, %dx%d, tile %d, channels %d, layers %d, flags 0x%x, codec %d level %s, "
              "area light %r at %r\n" % (h.major, h.minor, h.width, h.height, h.tile_size, h.channels,
                                         h.max_layers, h.required, h.codec, h.codec_level,
                                         h.area_light_radius, h.area_light_plane_depth))
    for l, L in enumerate(levels):
        out.write("level %d: %dx%d tolerance %r step %r bound %r vertices %d stored %d\n" % (
            l, L.width, L.height, L.tolerance, L.value_step, L.error_bound, L.vertex_count, L.stored_bytes))


def main(argv):
    if len(argv) < 2:
        sys.stderr.write(__doc__)
        return 2
    try:
        if argv[1] == "--summary":
            for path in argv[2:]:
                summary(path, sys.stdout)
        else:
            for path in argv[1:]:
                dump(path, sys.stdout)
    except (FormatError, OSError, zlib.error, struct.error, ValueError) as e:
        sys.stderr.write("dsm_reader.py: ERROR: %s\n" % e)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
