// Verilator testbench of fpga/rtl/spiv_tfp.sv: drives a .dat recording
// through the RTL, plane by plane, and holds every frame the RTL makes to
// the frame spiv-core makes through its C ABI (`spiv_make_frame`, the
// same TFP window on the same planes), sample for sample.
//
//   tb_tfp FILE.dat WINDOW FIRST DT EVERY
//
// The recording's size is the model's (W and H, set when verilated).
// Prints `frames=N planes=M missed=K equal` and exits 0, or names the
// first differing frame and sample and exits 1. A frame due on a plane
// that ended another (every == dt) is skipped by the RTL and counted, as
// here.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "Vspiv_tfp.h"
#include "read_file.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_W
#error "TB_W, TB_H and TB_P must match the model's W, H and P"
#endif

static const int W = TB_W, H = TB_H, P = TB_P;
static_assert(P == 32 || P == 64, "the testbench drives 32 or 64 pixels per clock");
static const int PX = W * H, BEATS = PX / P, PLANE_BYTES = PX / 8;

struct Bench {
    Vspiv_tfp m;
    std::vector<uint8_t> frame;  // the frame being received
    int got = 0;                 // samples of it received
    uint32_t tick = 0;           // its centre tick
    bool done = false;           // a whole frame is in `frame`

    void clock() {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
        if (m.out_valid) {
            if (m.out_start) {
                got = 0;
                tick = m.out_tick;
            }
            for (int l = 0; l < P && got < PX; ++l, ++got) {
                frame[got] = (m.out_gray[l / 4] >> (8 * (l % 4))) & 0xff;
            }
            if (got == PX) done = true;
        }
    }
};

int main(int argc, char** argv) {
    if (argc != 6) {
        std::fprintf(stderr, "usage: tb_tfp FILE.dat WINDOW FIRST DT EVERY\n");
        return 2;
    }
    const std::vector<uint8_t> dat = read_file(argv[1]);
    const uint16_t window = (uint16_t)std::atoi(argv[2]);
    const uint32_t first = (uint32_t)std::atol(argv[3]);
    const uint32_t dt = (uint32_t)std::atol(argv[4]);
    const uint32_t every = (uint32_t)std::atol(argv[5]);
    if (dat.empty() || dat.size() % PLANE_BYTES != 0) {
        std::fprintf(stderr, "%s: not whole %dx%d planes\n", argv[1], W, H);
        return 2;
    }
    const size_t planes = dat.size() / PLANE_BYTES;

    // The core, through its C ABI: frames on demand.
    SpivConfig cfg;
    if (spiv_config_default(W, H, dt, &cfg) != SPIV_OK) return 2;
    cfg.method = SPIV_METHOD_TFP;
    cfg.tfp_window = window;
    cfg.full_scale = 255;
    size_t bytes = 0;
    if (spiv_memory_size(&cfg, &bytes) != SPIV_OK) return 2;
    std::vector<uint64_t> memory((bytes + 7) / 8);
    SpivSidecar* sc = nullptr;
    if (spiv_init(&cfg, memory.data(), memory.size() * 8, &sc) != SPIV_OK) return 2;

    Bench b;
    b.frame.assign(PX, 0);
    b.m.window = (uint8_t)window;
    b.m.first = first;
    b.m.dt = dt;
    b.m.every = every;
    b.m.in_valid = 0;
    b.m.rst = 1;
    b.clock();
    b.clock();
    b.m.rst = 0;

    // The schedule, as the RTL's: centre ticks first + i*every (+ dt).
    uint32_t pair_k = first, next_k = first;
    bool member_b = false;
    // The frame after the next one.
    auto advance = [&]() {
        if (member_b) {
            pair_k += every;
            next_k = pair_k;
        } else {
            next_k = pair_k + dt;
        }
        member_b = !member_b;
    };
    const uint32_t half_up = (window + 1) / 2;
    size_t frames = 0, missed = 0;
    for (size_t t = 0; t < planes; ++t) {
        const uint8_t* plane = &dat[t * PLANE_BYTES];
        if (spiv_ingest(sc, plane, PLANE_BYTES, nullptr) != SPIV_OK) return 2;
        for (int beat = 0; beat < BEATS; ++beat) {
            b.m.in_valid = 1;
            uint64_t bits = 0;
            for (int l = 0; l < P; ++l) {
                const int p = beat * P + l;
                bits |= (uint64_t)((plane[p / 8] >> (p % 8)) & 1) << l;
            }
            b.m.in_bits = bits;
            b.clock();
        }
        b.m.in_valid = 0;
        for (int k = 0; k < 8; ++k) b.clock();
        const uint64_t due_tick = (uint64_t)next_k + half_up - 1;
        if (due_tick < t) {
            // Due on a plane that ended another frame: the RTL skips it.
            ++missed;
            advance();
        }
        const bool due = (uint64_t)next_k + half_up - 1 == t;
        if (due != b.done) {
            std::fprintf(stderr, "plane %zu: the RTL %s a frame, the schedule %s\n", t,
                         b.done ? "made" : "did not make", due ? "asks one" : "does not");
            return 1;
        }
        if (!due) continue;
        b.done = false;
        SpivFrameInfo info;
        const void* want = nullptr;
        if (spiv_make_frame(sc, next_k, nullptr, &info, &want) != SPIV_OK) {
            std::fprintf(stderr, "the core refused the frame at %u\n", next_k);
            return 2;
        }
        if (b.tick != next_k) {
            std::fprintf(stderr, "frame %zu: the RTL's tick %u, the core's %u\n", frames, b.tick, next_k);
            return 1;
        }
        const uint8_t* w8 = static_cast<const uint8_t*>(want);
        for (int p = 0; p < PX; ++p) {
            if (w8[p] != b.frame[p]) {
                std::fprintf(stderr, "frame at tick %u, pixel %d (row %d, column %d): RTL %u, core %u\n",
                             next_k, p, p / W, p % W, b.frame[p], w8[p]);
                return 1;
            }
        }
        ++frames;
        advance();
    }
    if (b.m.missed != missed) {
        std::fprintf(stderr, "the RTL counted %u missed frames, the schedule %zu\n", b.m.missed, missed);
        return 1;
    }
    std::printf("frames=%zu planes=%zu missed=%zu equal\n", frames, planes, missed);
    return frames > 0 ? 0 : 1;
}
