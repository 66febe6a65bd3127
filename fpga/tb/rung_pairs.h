// What the rung-frame testbenches (tb_rungs.cpp, tb_live.cpp) share: the
// recordings they run (a file, noise:N or dim:N), the pairs and flows they
// make, and the collection and comparison of a pair's frames from the RTL.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "core_light.h"
#include "read_file.h"

extern "C" {
#include "spiv_core.h"
}

// The planes of `spec`: FILE.dat as read; noise:N, N planes of each pixel
// spiking with probability 1/2; dim:N, N planes of each pixel spiking at
// random at its own rate, 1 in 500 to 1 in 10 ticks (log-uniform: pixels
// the light model predicts by their rate, at every rate).
static std::vector<uint8_t> recording(const char* spec, int PX) {
    const int PLANE_BYTES = PX / 8;
    std::vector<uint8_t> dat;
    if (std::strncmp(spec, "dim:", 4) == 0) {
        const size_t n = std::strtoul(spec + 4, nullptr, 10);
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
    } else if (std::strncmp(spec, "noise:", 6) == 0) {
        const size_t n = std::strtoul(spec + 6, nullptr, 10);
        uint64_t x = 0x2545F4914F6CDD1Dull;
        dat.resize(n * PLANE_BYTES);
        for (auto& b : dat) {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            b = (uint8_t)(x >> 24);
        }
    } else {
        dat = read_file(spec);
    }
    return dat;
}

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

// The pairs (module comment of tb_rungs.cpp) on a W x H image; `seed`
// draws the full-range nodes.
static std::vector<Case> rung_cases(int W, int H, uint64_t seed) {
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

// Clocks `m` (through `clock`, `before` called ahead of each clock) until
// it is done, gathers the frames it streams out (NR lanes, A and B each) and
// compares the first `n` lanes with the core's `want`, the rest with zero.
// Adds to `samples` and `nonzero`; 0 when equal, 1 (the first difference
// printed) when not.
template <int NR, class Model, class Clock, class Before>
static int compare_frames(Model& m, Clock clock, Before before, const Case& c, int W, int H,
                          int n, const std::vector<int16_t>& want, size_t& samples,
                          size_t& nonzero) {
    const int PX = W * H;
    std::vector<int16_t> got(2 * (size_t)NR * PX, 0x5555);
    size_t outs = 0;
    uint64_t guard = 0;
    for (;;) {
        before();
        clock();
        if (m.out_valid) {
            const uint32_t i = m.out_index;
            for (int k = 0; k < NR; ++k) {
                got[(2 * (size_t)k) * PX + i] = (int16_t)((m.out_a[k / 2] >> (16 * (k % 2))) & 0xffff);
                got[(2 * (size_t)k + 1) * PX + i] =
                    (int16_t)((m.out_b[k / 2] >> (16 * (k % 2))) & 0xffff);
            }
            ++outs;
        }
        if (m.done) break;
        if (++guard > 100000000ull) {
            std::fprintf(stderr, "%s: the RTL did not finish\n", c.name);
            return 1;
        }
    }
    if (m.error || outs != (size_t)PX) {
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
    return 0;
}
