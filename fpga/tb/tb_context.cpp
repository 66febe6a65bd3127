// Verilator testbench of fpga/rtl/spiv_context.sv: streams tiles through
// the RTL and holds every payload it makes to the one spiv-core makes
// through its C ABI (`spiv_encode_tile`, `SPIV_ENCODING_CONTEXT`), byte
// for byte, with the same choice of Context or raw and the same width
// flag, and counts the clocks each sample took.
//
//   tb_context [FILE.dat WIDTH HEIGHT]
//   tb_context frames FILE WIDTH HEIGHT
//
// The tiles: bands of 1, 7 and 16 rows of TFP-like frames of the
// recording (each pixel's spikes over 8 planes times 32, at most 255),
// when one is given; then synthetic tiles: all zero (every sample one
// bit), flat full scale, a ramp, 8-bit noise (raw), 16-bit noise (wide:
// residuals of 16 bits), levels alternating 0 and 65535 (the largest
// residuals), lone spikes after long runs of zeros, one-sample rows of
// noise and smooth ones of one and two samples (the line buffer read as it
// is written), a single sample, a sensor row of
// particles, rows of 400 and WMAX samples, every activity and brightness
// class (levels stepping by 0..80), long runs that make the coder's low
// word hold 0xFF bytes and carry into them, and noise tiles of many sizes
// whose payload comes near the raw tile's. With `frames`, only the live
// mode's rung frames that tb_rungs.cpp writes (TB_FRAMES), in bands of 16
// rows. Every tile goes through twice:
// back to back, and with in_valid low on a third of the clocks.
//
// Prints `tiles=N context=C raw=K ties=T bytes=B clocks/sample=R equal`
// and exits 0, or names the first differing tile and byte and exits 1.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "Vspiv_context.h"
#include "tiles.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_WMAX
#error "TB_WMAX must match the model's WMAX"
#endif

struct Bench {
    Vspiv_context m;
    uint32_t lcg = 12345;

    bool coin() {  // in_valid low on about a third of the clocks
        lcg = lcg * 1664525u + 1013904223u;
        return (lcg >> 24) % 3 == 0;
    }

    uint64_t clocks = 0, samples = 0;

    void clock(std::vector<uint8_t>& out, bool& done) {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
        for (int k = 0; k < 2; ++k) {
            if (!((m.out_valid >> (1 - k)) & 1)) continue;
            out.push_back((uint8_t)(m.out_head >> (8 * (1 - k))));
            const uint32_t count = (uint32_t)(m.out_count >> (32 * (1 - k)));
            const uint8_t fill = (uint8_t)(m.out_fill >> (8 * (1 - k)));
            if (count > 1u << 24) {
                std::fprintf(stderr, "a run of %u bytes\n", count);
                std::exit(1);
            }
            for (uint32_t i = 0; i < count; ++i) out.push_back(fill);
        }
        if (m.out_done) done = true;
    }

    // The tile through the RTL: its payload bytes, width flag and choice.
    // A sample is taken on a clock where in_valid and in_ready are both
    // high; clocks and samples count the back-to-back pass's rate.
    bool run(const Tile& t, bool pauses, std::vector<uint8_t>& out, bool& wide, bool& ctx,
             uint32_t& bytes) {
        out.clear();
        bool done = false;
        m.width = (uint16_t)t.width;
        const size_t n = t.s.size();
        for (size_t i = 0; i < n;) {
            const bool idle = pauses && coin();
            m.in_valid = !idle;
            m.in_first = !idle && i == 0;
            m.in_last = !idle && i + 1 == n;
            m.in_sample = t.s[i];
            m.eval();
            const bool taken = !idle && m.in_ready;
            clock(out, done);
            if (!pauses) ++clocks;
            if (taken) ++i;
            if (done) return false;  // the tile ended before its last sample
        }
        if (!pauses) samples += n;
        m.in_valid = 0;
        m.in_first = 0;
        m.in_last = 0;
        for (int k = 0; k < 4096 && !done; ++k) {
            clock(out, done);
            if (!pauses) ++clocks;
        }
        if (!done) return false;
        wide = m.out_wide;
        ctx = m.out_context;
        bytes = m.out_bytes;
        return true;
    }
};

int main(int argc, char** argv) {
    const int WMAX = TB_WMAX;
    std::vector<Tile> tiles;
    bool frames_only = false;
    if (argc == 4) {
        if (!recording_tiles(argv[1], std::atoi(argv[2]), std::atoi(argv[3]), WMAX, tiles))
            return 2;
    } else if (argc == 5 && std::string(argv[1]) == "frames") {
        // The live mode's rung frames as tb_rungs.cpp writes them: 16-bit
        // levels, WIDTH x HEIGHT each, in bands of 16 rows.
        const std::vector<uint8_t> raw = read_file(argv[2]);
        const int w = std::atoi(argv[3]), h = std::atoi(argv[4]);
        const size_t px = (size_t)w * h;
        if (w < 1 || w > WMAX || h < 1 || raw.empty() || raw.size() % (2 * px) != 0) {
            std::fprintf(stderr, "%s: not whole %dx%d frames of 16-bit levels\n", argv[2], w, h);
            return 2;
        }
        const size_t frames = raw.size() / (2 * px);
        for (size_t f = 0; f < frames; ++f)
            for (int r0 = 0; r0 < h; r0 += 16) {
                const int rows = std::min(16, h - r0);
                Tile t{"rung frame " + std::to_string(f) + " rows " + std::to_string(r0), w, rows, {}};
                for (size_t i = (size_t)r0 * w; i < (size_t)(r0 + rows) * w; ++i) {
                    const size_t at = 2 * (f * px + i);
                    t.s.push_back((uint16_t)(raw[at] | (raw[at + 1] << 8)));
                }
                tiles.push_back(t);
            }
        frames_only = true;
    } else if (argc != 1) {
        std::fprintf(stderr, "usage: tb_context [FILE.dat WIDTH HEIGHT | frames FILE WIDTH HEIGHT]\n");
        return 2;
    }
    if (!frames_only) {
        Lcg rnd;
        common_tiles(tiles, WMAX, rnd);
        // Rows of one and two samples, slowly varying: coded (not raw), so
        // the row above read as it is written is compared byte for byte.
        synth(tiles, "one-sample rows, smooth", 1, 300, [](int, int y) { return (y / 9) % 7 * 3; });
        synth(tiles, "two-sample rows, smooth", 2, 200, [](int x, int y) { return (y / 7) % 5 * 4 + x; });
        synth(tiles, "every class", 90, 12, [&](int x, int y) {
            const int step = (y * 7) % 81;  // activity 0..240 across a row
            return (x % 2 ? step : 0) + (y % 3) * 12;
        });
        // Residuals that put the low word at 0xFF.. for a while: the coder
        // holds those bytes, and a carry later turns them to 0x00.
        synth(tiles, "held bytes", 256, 16, [&](int x, int y) {
            return ((x * 31 + y * 17) % 251 < 3) ? rnd() % 256 : 255;
        });
        synth(tiles, "long zero run, then noise", 512, 16,
              [&](int x, int y) { return y < 14 ? 0 : (int)(rnd() % 256); });
        // Noise whose payload comes near the raw tile's length, over many
        // sizes and amplitudes: some tie with it (the core then sends raw).
        for (int amp = 4; amp <= 256; amp += 12)
            for (int width = 3; width <= 24; width += 3)
                synth(tiles, "near raw", width, 1 + width % 3, [&](int, int) { return rnd() % amp; });
    }

    Bench b;
    TileCounts n;
    if (!compare_tiles(b, tiles, SPIV_ENCODING_CONTEXT, "Context", WMAX, n)) return 1;
    std::printf("tiles=%d context=%d raw=%d ties=%d bytes=%zu clocks/sample=%.3f equal\n",
                n.tiles, n.coded, n.raw, n.ties, n.bytes, (double)b.clocks / (double)b.samples);
    return 0;
}
