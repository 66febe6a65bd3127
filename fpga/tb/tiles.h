// What the tile coders' testbenches (tb_rice.cpp, tb_context.cpp) share:
// the tiles of a recording, the synthetic tiles both coders take, and
// their comparison with the core.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "read_file.h"

extern "C" {
#include "spiv_core.h"
}

struct Tile {
    std::string name;
    int width, rows;
    std::vector<uint16_t> s;
};

// Bands of 1, 7 and 16 rows of TFP-like frames of the recording PATH
// (W x H planes): each pixel's spikes over 8 planes times 32, at most 255,
// from three places in the recording. False, with a message, when the
// file is not whole planes or is wider than WMAX.
static bool recording_tiles(const char* path, int w, int h, int wmax, std::vector<Tile>& tiles) {
    const std::vector<uint8_t> dat = read_file(path);
    const size_t plane = (size_t)w * h / 8;
    if (w < 1 || w > wmax || h < 1 || dat.empty() || dat.size() % plane != 0) {
        std::fprintf(stderr, "%s: not whole %dx%d planes, or wider than %d\n", path, w, h, wmax);
        return false;
    }
    const size_t planes = dat.size() / plane;
    for (size_t p0 = 0; p0 + 8 <= planes; p0 += planes / 3 > 8 ? planes / 3 : 8) {
        std::vector<uint16_t> frame((size_t)w * h, 0);
        for (size_t p = p0; p < p0 + 8; ++p)
            for (size_t i = 0; i < frame.size(); ++i)
                frame[i] += 32 * ((dat[p * plane + i / 8] >> (i % 8)) & 1);
        for (auto& v : frame) v = v > 255 ? 255 : v;
        for (int rows : {1, 7, 16}) {
            for (int r0 = 0; r0 + rows <= h; r0 += rows * 3) {
                Tile t{"frame " + std::to_string(p0) + " rows " + std::to_string(r0) + "+" +
                           std::to_string(rows),
                       w, rows, {}};
                t.s.assign(frame.begin() + (size_t)r0 * w, frame.begin() + (size_t)(r0 + rows) * w);
                tiles.push_back(t);
            }
        }
    }
    return true;
}

// The synthetic tiles' random levels (a linear congruential generator).
struct Lcg {
    uint32_t seed = 7;
    uint32_t operator()() {
        seed = seed * 1664525u + 1013904223u;
        return seed >> 8;
    }
};

// A WIDTH x ROWS tile whose sample at (x, y) is f(x, y).
template <class F>
static void synth(std::vector<Tile>& tiles, const char* name, int width, int rows, F f) {
    Tile t{name, width, rows, {}};
    for (int i = 0; i < width * rows; ++i) t.s.push_back((uint16_t)f(i % width, i / width));
    tiles.push_back(t);
}

// The synthetic tiles both coders take: all zero, flat full scale, a ramp,
// 8- and 16-bit noise, levels alternating 0 and 65535 (the largest
// residuals), lone spikes after long runs of zeros, one-sample rows of
// noise, a single sample, a sensor row of particles, a row of WMAX
// samples, and level 12 with lone 0s and 24s (residuals of -12 and +12:
// for Rice at k = 0, quotients 23, the longest plain code, and 24, the
// first escape).
static void common_tiles(std::vector<Tile>& tiles, int wmax, Lcg& rnd) {
    synth(tiles, "zero", 64, 8, [](int, int) { return 0; });
    synth(tiles, "flat 255", 64, 8, [](int, int) { return 255; });
    synth(tiles, "ramp", 100, 10, [](int x, int y) { return (3 * x + 5 * y) % 256; });
    synth(tiles, "noise 8-bit", 64, 8, [&](int, int) { return rnd() % 256; });
    synth(tiles, "noise 16-bit", 64, 8, [&](int, int) { return rnd() % 65536; });
    synth(tiles, "alternating 0/65535", 33, 5,
          [](int x, int y) { return ((x + y) % 2) ? 65535 : 0; });
    synth(tiles, "lone spikes", 128, 6,
          [](int x, int y) { return (x * 7 + y * 13) % 97 == 0 ? 255 : 0; });
    synth(tiles, "one-sample rows", 1, 40, [&](int, int) { return rnd() % 40; });
    synth(tiles, "one sample", 1, 1, [](int, int) { return 200; });
    synth(tiles, "sensor row", 400, 3,
          [&](int x, int) { return (x % 50 < 4) ? 180 + rnd() % 60 : rnd() % 4; });
    synth(tiles, "widest row", wmax, 2, [&](int x, int) { return (x * x) % 300; });
    synth(tiles, "steps of 12", 97, 6, [](int x, int y) {
        const int i = 97 * y + x;
        return i % 41 == 0 ? 0 : i % 53 == 0 ? 24 : 12;
    });
}

// What a run of the tiles found: tiles, coded (the coder's own coding),
// raw, raw tiles whose coded payload tied with the raw length, and the
// coded payloads' bytes.
struct TileCounts {
    int tiles = 0, coded = 0, raw = 0, ties = 0;
    size_t bytes = 0;
};

// Resets bench B (a coder's testbench: its model `m`, `clock` and `run`),
// then codes every tile twice, back to back and with in_valid low on a
// third of the clocks, and holds each to spiv_encode_tile(ENCODING): the
// same choice of coded or raw and width, and byte for byte when coded;
// raw in the core, the RTL's payload is no shorter than the raw tile.
// False, with a message naming the tile and the coder NAME, at the first
// difference.
template <class Bench>
static bool compare_tiles(Bench& b, const std::vector<Tile>& tiles, uint8_t encoding,
                          const char* name, size_t wmax, TileCounts& n) {
    b.m.rst = 1;
    b.m.in_valid = 0;
    b.m.width = 1;
    std::vector<uint8_t> junk;
    bool d = false;
    for (int k = 0; k < 4; ++k) b.clock(junk, d);
    b.m.rst = 0;

    std::vector<uint8_t> core(4 * wmax * 16 + 64), got;
    for (int pass = 0; pass < 2; ++pass) {
        for (const Tile& t : tiles) {
            uint8_t used = 0;
            size_t len = 0;
            if (spiv_encode_tile(encoding, t.s.data(), (uint16_t)t.width, (uint16_t)t.rows,
                                 core.data(), core.size(), &used, &len) != SPIV_OK) {
                std::fprintf(stderr, "%s: the core refused the tile\n", t.name.c_str());
                return false;
            }
            bool wide = false, coded = false;
            uint32_t bytes = 0;
            if (!b.run(t, pass == 1, got, wide, coded, bytes)) {
                std::fprintf(stderr, "%s: the RTL did not finish the tile\n", t.name.c_str());
                return false;
            }
            bool core_wide = false;
            for (uint16_t v : t.s) core_wide |= v > 255;
            const bool core_coded = used == encoding;
            if (wide != core_wide || coded != core_coded || got.size() != bytes) {
                std::fprintf(stderr,
                             "%s: RTL wide %d %s %d (%zu bytes, %u counted), core wide %d %s (%zu bytes)\n",
                             t.name.c_str(), wide, name, coded, got.size(), bytes, core_wide,
                             core_coded ? name : "raw", len);
                return false;
            }
            if (core_coded) {
                if (got.size() != len) {
                    std::fprintf(stderr, "%s: RTL %zu bytes, core %zu\n", t.name.c_str(),
                                 got.size(), len);
                    return false;
                }
                for (size_t i = 0; i < len; ++i) {
                    if (got[i] != core[i]) {
                        std::fprintf(stderr, "%s: byte %zu: RTL %02x, core %02x\n",
                                     t.name.c_str(), i, got[i], core[i]);
                        return false;
                    }
                }
                ++n.coded;
                n.bytes += len;
            } else {
                const size_t raw = t.s.size() * (core_wide ? 2 : 1);
                n.ties += got.size() == raw;
                if (got.size() < raw) {
                    std::fprintf(stderr, "%s: raw in the core, %zu %s bytes in the RTL\n",
                                 t.name.c_str(), got.size(), name);
                    return false;
                }
                ++n.raw;
            }
            ++n.tiles;
        }
    }
    return true;
}
