// Verilator testbench of fpga/rtl/spiv_rungs.sv: pushes a recording through
// spiv-core's static-light model and event ring (C ABI: spiv_ring_push),
// makes pairs of rung frames along several flows with the core
// (spiv_rung_frames) and with the RTL (fed the ring's events in its order,
// spiv_ring_events, and the light model's state), and compares every
// sample of every frame.
//
//   tb_rungs FILE.dat
//   tb_rungs noise:N      N planes, each pixel spiking with probability 1/2
//   tb_rungs dim:N        N planes, each pixel spiking at random at its own
//                         rate, 1 in 500 to 1 in 10 ticks
//
// The pairs: no motion; a uniform flow; a smooth field of rotation and
// shear with accelerations, on a grid smaller than the image (the flow
// extrapolated past its outer nodes); one node across and one down;
// full-range node values (displacements clamped, events carried out of
// the image); a flow that gathers the image onto its centre (samples that
// saturate while the events are added: a wrapping add fails it); at
// several sets of separations up to the longest the recording holds,
// eight rungs at once among them, 255 ticks, and the live loop's six (4
// to 128 ticks). A pitch that is not a power of two is refused by the RTL
// (and made by the core): the design takes the host's power-of-two grids
// only, and the testbench checks it refuses. Prints `pairs=N refused=R
// events=E samples=S nonzero=Z clocks=C equal` and exits 0, or names the
// first difference and exits 1; TB_VERBOSE=1 prints each pair's clocks,
// TB_FRAMES=FILE appends the core's frames to FILE as the live mode sends
// them, for tb_context.cpp.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "Vspiv_rungs.h"
#include "rung_pairs.h"
#include "verilated.h"

#ifndef TB_W
#error "TB_W, TB_H and TB_NR must match the model's W, H and NR"
#endif

static const int W = TB_W, H = TB_H, NR = TB_NR;
static const int PX = W * H, PLANE_BYTES = PX / 8;
static_assert(NR == 8, "the testbench drives eight lanes");

struct Bench {
    Vspiv_rungs m;
    uint64_t clocks = 0;
    void clock() {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
        ++clocks;
    }
};

int main(int argc, char** argv) {
    Verilated::commandArgs(argc, argv);
    if (argc < 2) {
        std::fprintf(stderr, "usage: tb_rungs FILE.dat | noise:N | dim:N\n");
        return 2;
    }
    const std::vector<uint8_t> dat = recording(argv[1], PX);
    const size_t planes = dat.size() / PLANE_BYTES;
    if (planes < 40) {
        std::fprintf(stderr, "%s: fewer than 40 planes of %d x %d\n", argv[1], W, H);
        return 2;
    }
    const uint32_t first = 1000;

    // The light model and a ring that loses nothing over the recording.
    CoreLight light(W, H, first);
    SpivLight& l = light.l;
    std::vector<uint32_t> entries(planes * (size_t)PX + 1), starts(planes + 2);
    SpivRing ring{entries.data(), entries.size(), starts.data(), planes + 1, 0, 0, 0, 0, 0};
    if (spiv_ring_init(&ring, first) != SPIV_OK) return 2;

    std::vector<Case> all = rung_cases(W, H, planes);
    Bench b;
    b.m.rst = 1;
    b.clock();
    b.clock();
    b.m.rst = 0;
    b.clock();

    size_t pushed = 0, made = 0, refused = 0, events_total = 0, samples = 0, nonzero = 0;
    for (size_t ci = 0; ci < all.size(); ++ci) {
        Case& c = all[ci];
        uint16_t longest = 0;
        for (uint16_t s : c.seps) longest = std::max(longest, s);
        // The pair's place: spread over the recording, after enough planes
        // for its longest rung on both sides.
        size_t need = 2 * (size_t)longest + 16;
        size_t at = std::max(need, (ci + 1) * planes / all.size());
        if (at > planes) {
            // Shorten the separations to what the recording holds.
            const uint16_t most = (uint16_t)((planes - 16) / 2);
            for (auto& s : c.seps) s = std::min(s, most);
            longest = std::min(longest, most);
            at = planes;
        }
        while (pushed < at) {
            if (spiv_ring_push(&ring, &l, W, H, &dat[pushed * PLANE_BYTES], PLANE_BYTES) != SPIV_OK)
                return 2;
            ++pushed;
        }
        if (ring.lost != 0 || ring.evicted != 0) {
            std::fprintf(stderr, "the ring lost events\n");
            return 2;
        }
        const uint32_t mid = ring.next - longest - 16;
        const int n = (int)c.seps.size();

        // The core's frames.
        SpivFlow f{(uint16_t)c.flow.nx, (uint16_t)c.flow.ny, c.flow.x0, c.flow.y0,
                   (uint16_t)c.flow.pitch, c.flow.vx.data(), c.flow.vy.data(),
                   c.flow.ax.data(), c.flow.ay.data()};
        std::vector<int16_t> want(2 * (size_t)n * PX);
        if (spiv_rung_frames(&ring, &l, W, H, &f, mid, c.seps.data(), n, want.data(), want.size()) !=
            SPIV_OK) {
            std::fprintf(stderr, "%s: the core refused the pair\n", c.name);
            return 2;
        }
        // TB_FRAMES=FILE appends the core's frames as the live mode sends
        // them (`rungs::send_pair`): each frame less its smallest sample,
        // in whole spikes (1/64), 16-bit little-endian, W x H each; the
        // Context coder's testbench codes them (fpga/check.sh).
        if (const char* path = std::getenv("TB_FRAMES")) {
            if (FILE* out = std::fopen(path, "ab")) {
                for (int k = 0; k < 2 * n; ++k) {
                    const int16_t* fr = &want[(size_t)k * PX];
                    int low = fr[0];
                    for (int i = 1; i < PX; ++i) low = std::min(low, (int)fr[i]);
                    std::vector<uint16_t> lv(PX);
                    for (int i = 0; i < PX; ++i) lv[i] = (uint16_t)((fr[i] - low) / 64);
                    std::fwrite(lv.data(), 2, lv.size(), out);
                }
                std::fclose(out);
            }
        }
        // The ring's events from before the longest rung's A (the RTL
        // leaves those out) to the last tick held.
        const uint32_t a = std::max(ring.first, mid - longest - 8);
        size_t nev = 0;
        spiv_ring_events(&ring, a, ring.next, nullptr, 0, &nev);
        std::vector<SpivEvent> ev(nev);
        if (spiv_ring_events(&ring, a, ring.next, ev.data(), ev.size(), &nev) != SPIV_OK) return 2;

        // The RTL: nodes, the pair, the events, the rates, the frames.
        for (int r = 0; r < c.flow.ny; ++r)
            for (int col = 0; col < c.flow.nx; ++col) {
                const int k = r * c.flow.nx + col;
                b.m.node_we = 1;
                b.m.node_r = r;
                b.m.node_c = col;
                b.m.node_vx = (uint16_t)c.flow.vx[k];
                b.m.node_vy = (uint16_t)c.flow.vy[k];
                b.m.node_ax = (uint16_t)c.flow.ax[k];
                b.m.node_ay = (uint16_t)c.flow.ay[k];
                b.clock();
            }
        b.m.node_we = 0;
        uint64_t seps = 0;
        for (int k = 0; k < n; ++k) seps |= (uint64_t)(c.seps[k] & 0xff) << (8 * k);
        b.m.mid = mid;
        b.m.nsep = n;
        b.m.seps = seps;
        b.m.nx = c.flow.nx;
        b.m.ny = c.flow.ny;
        b.m.x0 = (uint32_t)c.flow.x0;
        b.m.y0 = (uint32_t)c.flow.y0;
        b.m.pitch = c.flow.pitch;
        b.m.start = 1;
        b.clock();
        b.m.start = 0;
        if (c.refused_by_rtl) {
            if (!(b.m.done && b.m.error && !b.m.busy)) {
                std::fprintf(stderr, "%s: the RTL did not refuse the pair\n", c.name);
                return 1;
            }
            ++refused;
            continue;
        }
        // The tables take W + H clocks at most.
        for (int k = 0; k < W + H + 8 && !b.m.ev_ready && !b.m.done; ++k) b.clock();
        if (b.m.error || !b.m.ev_ready) {
            std::fprintf(stderr, "%s: the RTL refused the pair\n", c.name);
            return 1;
        }
        const uint64_t t0 = b.clocks;
        for (const SpivEvent& e : ev) {
            b.m.ev_valid = 1;
            b.m.ev_index = e.index;
            b.m.ev_tick = e.tick;
            b.m.ev_neg = e.sign < 0;
            b.clock();
        }
        b.m.ev_valid = 0;
        b.m.ev_end = 1;
        b.clock();
        b.m.ev_end = 0;
        const uint64_t t_events = b.clocks - t0;
        if (compare_frames<NR>(
                b.m, [&] { b.clock(); },
                [&] {
                    // The state word of the pixel asked for, as a block RAM gives it.
                    const uint32_t p = b.m.rate_addr;
                    if (p < (uint32_t)PX) {
                        b.m.rate_q24 = light.rate[p];
                        b.m.rate_flags = light.flags[p];
                    }
                },
                c, W, H, n, want, samples, nonzero) != 0)
            return 1;
        if (std::getenv("TB_VERBOSE"))
            std::fprintf(stderr, "  %-16s mid %u, %zu events: %llu clocks of events, %llu in all\n", c.name,
                     mid, ev.size(), (unsigned long long)t_events, (unsigned long long)(b.clocks - t0));
        events_total += ev.size();
        ++made;
    }
    std::printf("pairs=%zu refused=%zu events=%zu samples=%zu nonzero=%zu clocks=%llu equal\n",
                made, refused, events_total, samples, nonzero,
                (unsigned long long)b.clocks);
    return made > 0 && nonzero > 0 ? 0 : 1;
}
