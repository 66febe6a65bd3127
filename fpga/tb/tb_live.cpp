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
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "Vspiv_live.h"
#include "read_file.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_W
#error "TB_W, TB_H, TB_P, TB_NR, TB_CAPB and TB_DEPB must match the model's"
#endif

static const int W = TB_W, H = TB_H, NR = TB_NR;
static const int PX = W * H, PLANE_BYTES = PX / 8;
static_assert(NR == 8, "the testbench drives eight lanes");

struct Flow {
    int nx = 0, ny = 0, x0 = 0, y0 = 0, pitch = 16;
    std::vector<int16_t> vx, vy, ax, ay;
    void size(int cols, int rows) {
        nx = cols;
        ny = rows;
        vx.assign(cols * rows, 0);
        vy = ax = ay = vx;
    }
};

struct Case {
    const char* name;
    std::vector<uint16_t> seps;
    Flow flow;
    bool refused_by_rtl;
};

static int16_t clamp16(double v) {
    return (int16_t)std::max(-32768.0, std::min(32767.0, std::round(v)));
}

static std::vector<Case> cases(uint64_t seed) {
    uint64_t x = seed * 0x9E3779B97F4A7C15ull + 7;
    auto next = [&x]() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return x;
    };
    std::vector<Case> out;
    out.push_back({"still", {4, 8, 16, 32}, Flow{}, false});
    {
        // 0.3 px/tick right, 0.2 up, nodes every 16 px from (8, 8).
        Flow f;
        f.size(W / 16, H / 16);
        f.pitch = 256;
        f.x0 = f.y0 = 8 * 16;
        std::fill(f.vx.begin(), f.vx.end(), clamp16(0.3 * 4096));
        std::fill(f.vy.begin(), f.vy.end(), clamp16(-0.2 * 4096));
        out.push_back({"uniform", {4, 8, 16, 32, 64}, f, false});
    }
    {
        // Rotation and shear on 8-px nodes over the middle of the image,
        // with (v.grad)v accelerations; extrapolated one node beyond, then
        // constant.
        Flow f;
        f.size(W / 8 - 4, H / 8 - 3);
        f.pitch = 128;
        f.x0 = 20 * 16 + 3;
        f.y0 = -5;
        for (int r = 0; r < f.ny; ++r)
            for (int c = 0; c < f.nx; ++c) {
                const double u = 0.8 * std::sin(0.4 * r) + 0.1 * c / f.nx;
                const double v = -0.6 * std::cos(0.3 * c);
                const int k = r * f.nx + c;
                f.vx[k] = clamp16(u * 4096);
                f.vy[k] = clamp16(v * 4096);
                f.ax[k] = clamp16(0.02 * std::cos(0.5 * r + c) * 65536);
                f.ay[k] = clamp16(-0.015 * std::sin(0.2 * c - r) * 65536);
            }
        out.push_back({"rotation", {2, 3, 5, 9, 17, 33, 60, 7}, f, false});
    }
    {
        Flow f;
        f.size(1, 4);
        f.pitch = 4096;
        f.x0 = 100;
        f.y0 = -3000;
        for (int r = 0; r < 4; ++r) {
            f.vx[r] = clamp16(0.5 * 4096 * (r - 1.5));
            f.vy[r] = clamp16(0.25 * 4096);
            f.ay[r] = (int16_t)(300 * r - 400);
        }
        out.push_back({"one node across", {16, 40}, f, false});
        Flow g;
        g.size(5, 1);
        g.pitch = 16;
        g.x0 = 60 * 16;
        g.y0 = 10;
        for (int c = 0; c < 5; ++c) {
            g.vx[c] = (int16_t)(800 * c - 1600);
            g.vy[c] = (int16_t)(2000 - 700 * c);
            g.ax[c] = (int16_t)(-90 * c);
        }
        out.push_back({"one node down", {3, 31}, g, false});
    }
    {
        // Any 16-bit node values: displacements past i16, events carried
        // out of the image.
        Flow f;
        f.size(W / 4 + 2, H / 4 + 2);
        f.pitch = 64;
        f.x0 = -16;
        f.y0 = 40;
        for (int k = 0; k < f.nx * f.ny; ++k) {
            f.vx[k] = (int16_t)next();
            f.vy[k] = (int16_t)next();
            f.ax[k] = (int16_t)next();
            f.ay[k] = (int16_t)next();
        }
        out.push_back({"full range", {8, 24, 50}, f, false});
    }
    {
        // Four corner nodes 128 px apart moving inwards at 8 px per tick:
        // 8 ticks from a frame's centre the whole image lands on its
        // middle pixel, and the samples there saturate.
        Flow f;
        f.size(2, 2);
        f.pitch = 2048;
        f.x0 = (W / 2 - 64) * 16;
        f.y0 = (H / 2 - 64) * 16;
        for (int r = 0; r < 2; ++r)
            for (int c = 0; c < 2; ++c) {
                f.vx[r * 2 + c] = (int16_t)(c ? -32767 : 32767);
                f.vy[r * 2 + c] = (int16_t)(r ? -32767 : 32767);
            }
        out.push_back({"gathering", {33, 65}, f, false});
    }
    {
        // The longest separations a pair takes (255 ticks: d2 up to 254
        // half ticks) along a shear on 32-px nodes.
        Flow f;
        f.size(W / 32 + 1, H / 32 + 1);
        f.pitch = 512;
        f.x0 = f.y0 = 0;
        for (int r = 0; r < f.ny; ++r)
            for (int c = 0; c < f.nx; ++c) {
                f.vx[r * f.nx + c] = clamp16(0.05 * 4096 * (r - 1));
                f.vy[r * f.nx + c] = clamp16(-0.03 * 4096 * c);
                f.ax[r * f.nx + c] = clamp16(-0.0015 * 65536 * c * (r - 1));
            }
        out.push_back({"longest", {130, 200, 255}, f, false});
    }
    {
        // The live loop's rungs (4 to 128 ticks) along the uniform flow.
        Case u = out[1];
        u.name = "live rungs";
        u.seps = {4, 8, 16, 32, 64, 128};
        out.push_back(u);
    }
    {
        Flow f;
        f.size(3, 3);
        f.pitch = 192;  // 12 px: not a power of two
        f.vx.assign(9, 1000);
        out.push_back({"pitch 12 px", {8}, f, true});
    }
    return out;
}

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
    std::vector<uint8_t> dat;
    if (std::strncmp(argv[1], "dim:", 4) == 0) {
        // Each pixel spiking at random at its own rate, 1 in 500 to 1 in 10
        // ticks (log-uniform): pixels the light model predicts by their
        // rate, at every rate.
        const size_t n = std::strtoul(argv[1] + 4, nullptr, 10);
        uint64_t x = 0x9E3779B97F4A7C15ull;
        auto next = [&x]() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            return (double)(x >> 11) / 9007199254740992.0;
        };
        std::vector<double> q(PX);
        for (auto& v : q) v = 0.002 * std::pow(50.0, next());
        dat.assign(n * PLANE_BYTES, 0);
        for (size_t t = 0; t < n; ++t)
            for (int p = 0; p < PX; ++p)
                if (next() < q[p]) dat[t * PLANE_BYTES + p / 8] |= (uint8_t)(1u << (p % 8));
    } else if (std::strncmp(argv[1], "noise:", 6) == 0) {
        const size_t n = std::strtoul(argv[1] + 6, nullptr, 10);
        uint64_t x = 0x2545F4914F6CDD1Dull;
        dat.resize(n * PLANE_BYTES);
        for (auto& b : dat) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            b = (uint8_t)(x >> 24);
        }
    } else {
        dat = read_file(argv[1]);
    }
    const size_t planes = dat.size() / PLANE_BYTES;
    if (planes < 40) {
        std::fprintf(stderr, "%s: fewer than 40 planes of %d x %d\n", argv[1], W, H);
        return 2;
    }
    const uint32_t first = 1000;

    // The light model and a ring that loses nothing over the recording.
    std::vector<uint16_t> last(PX), period(PX), short_run(PX);
    std::vector<uint32_t> rate(PX);
    std::vector<int8_t> lead(PX);
    std::vector<uint8_t> flags(PX);
    SpivLight l{last.data(), period.data(), rate.data(), short_run.data(),
                lead.data(), flags.data(), (size_t)PX, 0, 0};
    if (spiv_light_init(&l, W, H, first) != SPIV_OK) return 2;
    const size_t cap = (size_t)1 << TB_CAPB, depth = ((size_t)1 << TB_DEPB) - 1;
    std::vector<uint32_t> entries(cap), starts(depth + 1);
    SpivRing ring{entries.data(), cap, starts.data(), depth, 0, 0, 0, 0, 0};
    if (spiv_ring_init(&ring, first) != SPIV_OK) return 2;

    std::vector<Case> all = cases(planes);
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
        std::vector<int16_t> got(2 * (size_t)NR * PX, 0x5555);
        size_t outs = 0;
        uint64_t guard = 0;
        for (;;) {
            b.clock();
            if (b.m.out_valid) {
                const uint32_t i = b.m.out_index;
                for (int k = 0; k < NR; ++k) {
                    got[(2 * (size_t)k) * PX + i] = (int16_t)((b.m.out_a[k / 2] >> (16 * (k % 2))) & 0xffff);
                    got[(2 * (size_t)k + 1) * PX + i] =
                        (int16_t)((b.m.out_b[k / 2] >> (16 * (k % 2))) & 0xffff);
                }
                ++outs;
            }
            if (b.m.done) break;
            if (++guard > 100000000ull) {
                std::fprintf(stderr, "%s: the RTL did not finish\n", c.name);
                return 1;
            }
        }
        if (b.m.error || outs != (size_t)PX) {
            std::fprintf(stderr, "%s: %zu samples out, %d asked\n", c.name, outs, PX);
            return 1;
        }
        for (int k = 0; k < n; ++k)
            for (int h = 0; h < 2; ++h)
                for (int p = 0; p < PX; ++p) {
                    const int16_t wv = want[(2 * (size_t)k + h) * PX + p];
                    const int16_t gv = got[(2 * (size_t)k + h) * PX + p];
                    if (wv != gv) {
                        std::fprintf(stderr,
                                     "%s: rung %d (%u ticks), frame %c, pixel %d (row %d, column %d): "
                                     "RTL %d, core %d\n",
                                     c.name, k, c.seps[k], h ? 'B' : 'A', p, p / W, p % W, gv, wv);
                        return 1;
                    }
                    ++samples;
                    if (wv != 0) ++nonzero;
                }
        for (int k = n; k < NR; ++k)
            for (int h = 0; h < 2; ++h)
                for (int p = 0; p < PX; ++p)
                    if (got[(2 * (size_t)k + h) * PX + p] != 0) {
                        std::fprintf(stderr, "%s: unused lane %d made a sample\n", c.name, k);
                        return 1;
                    }
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
