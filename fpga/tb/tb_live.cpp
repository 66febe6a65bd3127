// Verilator testbench of fpga/rtl/spiv_live.sv, the live mode's frame
// pipeline in RTL: spike planes go into the RTL's light model, ring and
// rung frames, and into spiv-core's (`spiv_ring_push` through the core's
// light model into a ring of the same size); at each pair every sample of
// every frame must equal `spiv_rung_frames`'. The pairs and flows are
// tb_rungs.cpp's; each pair made is asked again a tick late, which both
// refuse.
//
//   tb_live FILE.dat | noise:N | dim:N
//
// Prints `pairs=N refused=R events=E evicted=V samples=S nonzero=Z
// clocks=C equal` and exits 0, or names the first difference and exits 1.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "Vspiv_live.h"
#include "rung_pairs.h"
#include "verilated.h"

#ifndef TB_W
#error "TB_W, TB_H, TB_P, TB_NR, TB_CAPB and TB_DEPB must match the model's"
#endif

static const int W = TB_W, H = TB_H, NR = TB_NR;
static const int PX = W * H, PLANE_BYTES = PX / 8;
static_assert(NR == 8, "the testbench drives eight lanes");

struct Bench {
    Vspiv_live m;
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
        std::fprintf(stderr, "usage: tb_live FILE.dat | noise:N | dim:N\n");
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
    const size_t cap = (size_t)1 << TB_CAPB, depth = ((size_t)1 << TB_DEPB) - 1;
    std::vector<uint32_t> entries(cap), starts(depth + 1);
    SpivRing ring{entries.data(), cap, starts.data(), depth, 0, 0, 0, 0, 0};
    if (spiv_ring_init(&ring, first) != SPIV_OK) return 2;

    std::vector<Case> all = rung_cases(W, H, planes);
    Bench b;
    b.m.first_tick = first;
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
            const uint8_t* plane = &dat[pushed * PLANE_BYTES];
            if (spiv_ring_push(&ring, &l, W, H, plane, PLANE_BYTES) != SPIV_OK) return 2;
            // The plane into the RTL, TB_P pixels per beat, pausing when it
            // asks; then until the ring has closed the plane's tick.
            for (int beat = 0; beat < PX / TB_P;) {
                b.m.in_valid = 0;
                if (b.m.in_ready) {
                    uint32_t bits = 0;
                    for (int l = 0; l < TB_P; ++l) {
                        const int p = beat * TB_P + l;
                        bits |= (uint32_t)((plane[p / 8] >> (p % 8)) & 1) << l;
                    }
                    b.m.in_valid = 1;
                    b.m.in_bits = bits;
                    ++beat;
                }
                b.clock();
            }
            b.m.in_valid = 0;
            for (uint64_t k = 0; b.m.ring_next != first + (uint32_t)pushed + 1; ++k) {
                if (k > 4 * (uint64_t)PX + 1000) {
                    std::fprintf(stderr, "plane %zu: the RTL did not close it\n", pushed);
                    return 1;
                }
                b.clock();
            }
            ++pushed;
        }
        if (b.m.ring_bad_tick || b.m.ring_first != ring.first || b.m.ring_next != ring.next ||
            b.m.ring_stored != ring.stored || b.m.ring_lost != ring.lost ||
            b.m.ring_evicted != ring.evicted) {
            std::fprintf(stderr, "%s: the rings differ (RTL stored %u lost %u evicted %u, core %u %u %u)\n",
                         c.name, b.m.ring_stored, b.m.ring_lost, b.m.ring_evicted, ring.stored,
                         ring.lost, ring.evicted);
            return 1;
        }
        const uint32_t mid = ring.next - longest - 16;
        const int n = (int)c.seps.size();

        // The core's frames.
        SpivFlow f{(uint16_t)c.flow.nx, (uint16_t)c.flow.ny, c.flow.x0, c.flow.y0,
                   (uint16_t)c.flow.pitch, c.flow.vx.data(), c.flow.vy.data(),
                   c.flow.ax.data(), c.flow.ay.data()};
        std::vector<int16_t> want(2 * (size_t)n * PX);
        const SpivStatus st =
            spiv_rung_frames(&ring, &l, W, H, &f, mid, c.seps.data(), n, want.data(), want.size());
        // A pair whose ticks the ring no longer holds: both refuse it.
        const bool unheld = st == SPIV_ERR_TICK;
        if (st != SPIV_OK && !unheld) {
            std::fprintf(stderr, "%s: the core refused the pair\n", c.name);
            return 2;
        }
        // The ring's events from before the longest rung's A (the RTL
        // leaves those out) to the last tick held: the RTL's reader reads
        // them from its own ring.
        const uint32_t a = std::max(ring.first, mid - longest - 8);
        size_t nev = 0;
        spiv_ring_events(&ring, a, ring.next, nullptr, 0, &nev);

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
        b.m.ev_from = a;
        b.m.start = 1;
        b.clock();
        b.m.start = 0;
        if (c.refused_by_rtl || unheld) {
            if (!(b.m.done && b.m.error && !b.m.busy)) {
                std::fprintf(stderr, "%s: the RTL did not refuse the pair\n", c.name);
                return 1;
            }
            ++refused;
            continue;
        }
        if (b.m.error) {
            std::fprintf(stderr, "%s: the RTL refused the pair\n", c.name);
            return 1;
        }
        const uint64_t t0 = b.clocks;
        if (compare_frames<NR>(
                b.m, [&] { b.clock(); },
                [] {},
                c, W, H, n, want, samples, nonzero) != 0)
            return 1;
        if (std::getenv("TB_VERBOSE"))
            std::fprintf(stderr, "  %-16s mid %u, %zu events, %llu clocks\n", c.name, mid, nev,
                         (unsigned long long)(b.clocks - t0));
        events_total += nev;
        ++made;
        // The same pair a tick later needs a tick the ring does not hold
        // yet: the core refuses it, and so must the RTL.
        if (spiv_rung_frames(&ring, &l, W, H, &f, mid + 1, c.seps.data(), n, want.data(),
                             want.size()) != SPIV_ERR_TICK) {
            std::fprintf(stderr, "%s: the core took the pair a tick late\n", c.name);
            return 2;
        }
        b.m.mid = mid + 1;
        b.m.start = 1;
        b.clock();
        b.m.start = 0;
        if (!(b.m.done && b.m.error && !b.m.busy)) {
            std::fprintf(stderr, "%s: the RTL took the pair a tick late\n", c.name);
            return 1;
        }
        ++refused;
    }
    std::printf("pairs=%zu refused=%zu events=%zu evicted=%u samples=%zu nonzero=%zu clocks=%llu equal\n",
                made, refused, events_total, ring.evicted, samples, nonzero,
                (unsigned long long)b.clocks);
    return made > 0 && nonzero > 0 ? 0 : 1;
}
