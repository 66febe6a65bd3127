// Verilator testbench of fpga/rtl/spiv_rice.sv: streams tiles through
// the RTL and holds every payload it makes to the one spiv-core makes
// through its C ABI (`spiv_encode_tile`, `SPIV_ENCODING_RICE`), byte for
// byte, with the same choice of Rice or raw and the same width flag.
//
//   tb_rice [FILE.dat WIDTH HEIGHT]
//
// The tiles: bands of 1, 7 and 16 rows of TFP-like frames of the
// recording (each pixel's spikes over 8 planes times 32, at most 255),
// when one is given; then synthetic tiles: all zero, flat full scale, a
// ramp, 8-bit noise (raw), 16-bit noise (wide, escapes, k up to 16),
// levels alternating 0 and 65535 (the largest residuals), lone spikes
// after long runs of zeros (escapes at k = 0), one-sample rows, a single
// sample, rows of 400 and WMAX samples, lone residuals of +-12 at k = 0
// (quotients 23 and 24: the longest plain code and the first escape),
// and noise tiles of many sizes whose payload comes near the raw tile's
// (`ties`: as long as it, sent raw). Every tile goes through twice:
// back to back, and with in_valid low on a third of the clocks.
//
// Prints `tiles=N rice=R raw=K ties=T bytes=B equal` and exits 0, or names the
// first differing tile and byte and exits 1.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "Vspiv_rice.h"
#include "tiles.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_WMAX
#error "TB_WMAX must match the model's WMAX"
#endif

struct Bench {
    Vspiv_rice m;
    uint32_t lcg = 12345;

    bool coin() {  // in_valid low on about a third of the clocks
        lcg = lcg * 1664525u + 1013904223u;
        return (lcg >> 24) % 3 == 0;
    }

    void clock(std::vector<uint8_t>& out, bool& done) {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
        for (int w = 0; w < m.out_words; ++w) {
            uint32_t word = (uint32_t)(m.out_data >> (32 * (1 - w)));
            for (int b = 3; b >= 0; --b) out.push_back((uint8_t)(word >> (8 * b)));
        }
        if (m.out_done) {
            for (int b = 0; b < m.out_tail_bytes; ++b)
                out.push_back((uint8_t)(m.out_tail >> (24 - 8 * b)));
            done = true;
        }
    }

    // The tile through the RTL: its payload bytes, width flag and choice.
    bool run(const Tile& t, bool pauses, std::vector<uint8_t>& out, bool& wide, bool& rice,
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
            clock(out, done);
            if (!idle) ++i;
        }
        m.in_valid = 0;
        m.in_first = 0;
        m.in_last = 0;
        for (int k = 0; k < 16 && !done; ++k) clock(out, done);
        if (!done) return false;
        wide = m.out_wide;
        rice = m.out_rice;
        bytes = m.out_bytes;
        return true;
    }
};

int main(int argc, char** argv) {
    const int WMAX = TB_WMAX;
    std::vector<Tile> tiles;
    if (argc == 4) {
        if (!recording_tiles(argv[1], std::atoi(argv[2]), std::atoi(argv[3]), WMAX, tiles))
            return 2;
    } else if (argc != 1) {
        std::fprintf(stderr, "usage: tb_rice [FILE.dat WIDTH HEIGHT]\n");
        return 2;
    }
    Lcg rnd;
    common_tiles(tiles, WMAX, rnd);
    // Noise whose payload comes near the raw tile's length, over many
    // sizes and amplitudes: some tie with it (the core then sends raw).
    for (int amp = 64; amp <= 256; amp += 16)
        for (int width = 3; width <= 24; width += 3)
            synth(tiles, "near raw", width, 1 + width % 3, [&](int, int) { return rnd() % amp; });

    Bench b;
    TileCounts n;
    if (!compare_tiles(b, tiles, SPIV_ENCODING_RICE, "Rice", WMAX, n)) return 1;
    std::printf("tiles=%d rice=%d raw=%d ties=%d bytes=%zu equal\n", n.tiles, n.coded, n.raw, n.ties,
                n.bytes);
    return 0;
}
