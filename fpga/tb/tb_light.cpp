// Verilator testbench of fpga/rtl/spiv_light.sv: drives a .dat recording
// through the RTL, plane by plane, and holds it to spiv-core's static-light
// model through its C ABI (`spiv_light_push` on the same planes): every
// pixel's event (+1 at the plane's tick, -1 `late` ticks before it, or
// none) and every pixel's state after every plane.
//
//   tb_light FILE.dat FIRST [pause]
//   tb_light synth:N FIRST [pause]
//
// `synth:N` is N planes made here: integrate-and-fire pixels under steady
// light from 1.2 spikes per tick down to one spike in 6,000 ticks (past
// the longest period the model holds), a little photon noise, and bright
// particles crossing now and then. FIRST is the first plane's tick (near 65536 to cross the 16-bit tick's
// wrap); `pause` drops in_valid every third clock (planes otherwise
// stream back to back). The recording's size is the model's (W and H, set
// when verilated). Prints `planes=N events=E equal` and exits 0, or names
// the first difference and exits 1.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "Vspiv_light.h"
#include "core_light.h"
#include "read_file.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_W
#error "TB_W, TB_H and TB_P must match the model's W, H and P"
#endif

static const int W = TB_W, H = TB_H, P = TB_P;
static_assert(P == 8 || P == 32, "the testbench drives 8 or 32 pixels per clock");
static const int PX = W * H, BEATS = PX / P, PLANE_BYTES = PX / 8, SB = 78;

// The core's state and events after one plane.
struct Snapshot {
    std::vector<uint16_t> last, period, short_run;
    std::vector<uint32_t> rate;
    std::vector<int8_t> lead;
    std::vector<uint8_t> flags;
    std::vector<int8_t> sign;     // per pixel: 0, +1 or -1
    std::vector<uint32_t> tick;   // the event's tick
    uint32_t plane_tick = 0;
};

template <class Wide>
static uint32_t field(const Wide& w, int lo, int n) {
    uint32_t v = 0;
    for (int i = 0; i < n; ++i) v |= ((w[(lo + i) / 32] >> ((lo + i) % 32)) & 1u) << i;
    return v;
}

// `planes` planes of the synthetic scene (see the usage above), seeded.
static std::vector<uint8_t> synthetic(size_t planes, uint64_t seed) {
    uint64_t x = seed * 0x9E3779B97F4A7C15ull + 1;
    auto next = [&x]() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return (double)(x >> 11) / 9007199254740992.0;  // [0, 1)
    };
    std::vector<double> q(PX), v(PX);
    for (int p = 0; p < PX; ++p) {
        q[p] = 1.2 * std::pow(1.0 / 7200.0, next());  // log-uniform
        v[p] = next();
    }
    std::vector<uint8_t> out(planes * PLANE_BYTES, 0);
    double px = 0, py = 0, vx = 0, vy = 0;
    size_t until = 0;
    for (size_t t = 0; t < planes; ++t) {
        if (t >= until) {  // a new particle: position, velocity, life
            px = next() * W;
            py = next() * H;
            vx = (next() - 0.5) * 2.0;
            vy = (next() - 0.5) * 2.0;
            until = t + 20 + (size_t)(next() * 200);
        }
        px += vx;
        py += vy;
        for (int p = 0; p < PX; ++p) {
            const double dx = p % W - px, dy = p / W - py;
            const double particle = dx * dx + dy * dy < 4.0 ? 0.7 : 0.0;
            v[p] += q[p] * (1.0 + 0.05 * (next() - 0.5)) + particle;
            if (v[p] >= 1.0) {
                v[p] -= 1.0;
                if (v[p] >= 1.0) v[p] = 0.0;
                out[t * PLANE_BYTES + p / 8] |= (uint8_t)(1u << (p % 8));
            }
        }
    }
    return out;
}

// Bits lo..lo + n of an output port, narrow or wide.
static uint32_t lanes(uint64_t v, int lo, int n) {
    return (uint32_t)((v >> lo) & ((1ull << n) - 1));
}
template <std::size_t N>
static uint32_t lanes(const VlWide<N>& w, int lo, int n) {
    return field(w, lo, n);
}

int main(int argc, char** argv) {
    if (argc != 3 && argc != 4) {
        std::fprintf(stderr, "usage: tb_light FILE.dat FIRST [pause]\n");
        return 2;
    }
    const std::vector<uint8_t> dat =
        std::strncmp(argv[1], "synth:", 6) == 0
            ? synthetic((size_t)std::strtoul(argv[1] + 6, nullptr, 10), 7)
            : read_file(argv[1]);
    const uint32_t first = (uint32_t)std::strtoul(argv[2], nullptr, 10);
    const bool pause = argc == 4 && std::strcmp(argv[3], "pause") == 0;
    if (dat.empty() || dat.size() % PLANE_BYTES != 0) {
        std::fprintf(stderr, "%s: not whole %dx%d planes\n", argv[1], W, H);
        return 2;
    }
    const size_t planes = dat.size() / PLANE_BYTES;

    // The core's model, through its C ABI.
    CoreLight core(W, H, first);
    SpivLight& light = core.l;
    std::vector<SpivEvent> events(PX);
    // The core's plane `t`, as the RTL's first beat of it comes out.
    Snapshot s;
    size_t total = 0;
    auto reference = [&](size_t t) -> bool {
        s.plane_tick = light.next;
        size_t n = 0;
        if (spiv_light_push(&light, W, H, &dat[t * PLANE_BYTES], PLANE_BYTES, events.data(),
                            events.size(), &n) != SPIV_OK)
            return false;
        s.last = core.last;
        s.period = core.period;
        s.short_run = core.short_run;
        s.rate = core.rate;
        s.lead = core.lead;
        s.flags = core.flags;
        s.sign.assign(PX, 0);
        s.tick.assign(PX, 0);
        for (size_t e = 0; e < n; ++e) {
            s.sign[events[e].index] = events[e].sign;
            s.tick[events[e].index] = events[e].tick;
        }
        total += n;
        return true;
    };

    Vspiv_light m;
    auto clock = [&m]() {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
    };
    m.first = first;
    m.in_valid = 0;
    m.rst = 1;
    clock();
    clock();
    m.rst = 0;

    size_t got = 0;  // beats out so far
    const size_t beats = planes * BEATS;
    // Checks the beat that came out: pixels got*P .. got*P + P - 1.
    auto check = [&]() -> bool {
        const size_t t = got / BEATS;
        if (got % BEATS == 0 && !reference(t)) {
            std::fprintf(stderr, "the core refused plane %zu\n", t);
            return false;
        }
        if (m.out_tick != s.plane_tick) {
            std::fprintf(stderr, "plane %zu: the RTL's tick %u, the core's %u\n", t, m.out_tick,
                         s.plane_tick);
            return false;
        }
        for (int l = 0; l < P; ++l) {
            const int p = (int)(got % BEATS) * P + l;
            const int plus = lanes(m.out_plus, l, 1), minus = lanes(m.out_minus, l, 1);
            const uint32_t late = lanes(m.out_late, 5 * l, 5);
            int sign = plus ? 1 : minus ? -1 : 0;
            uint32_t tick = plus ? m.out_tick : m.out_tick - late;
            if (plus && minus) sign = 2;
            const int lo = SB * l;
            const uint32_t count = field(m.out_state, lo, 3), spiked = field(m.out_state, lo + 3, 1);
            const int8_t ld = (int8_t)field(m.out_state, lo + 4, 8);
            const uint32_t sh = field(m.out_state, lo + 12, 9), rt = field(m.out_state, lo + 21, 25);
            const uint32_t per = field(m.out_state, lo + 46, 16), ls = field(m.out_state, lo + 62, 16);
            const uint8_t fl = (uint8_t)(spiked << 7 | count);
            if (sign != s.sign[p] || (sign != 0 && tick != s.tick[p]) || ls != s.last[p] ||
                per != s.period[p] || sh != s.short_run[p] || rt != s.rate[p] || ld != s.lead[p] ||
                fl != s.flags[p]) {
                std::fprintf(stderr,
                             "plane %zu (tick %u), pixel %d: RTL event %d@%u last %u period %u "
                             "short %u rate %u lead %d flags %02x; core event %d@%u last %u "
                             "period %u short %u rate %u lead %d flags %02x\n",
                             t, s.plane_tick, p, sign, tick, ls, per, sh, rt, ld, fl, s.sign[p],
                             s.tick[p], s.last[p], s.period[p], s.short_run[p], s.rate[p],
                             s.lead[p], s.flags[p]);
                return false;
            }
        }
        return true;
    };

    size_t fed = 0, cycle = 0;
    while (got < beats) {
        const bool feed = fed < beats && !(pause && cycle % 3 == 2);
        m.in_valid = feed;
        if (feed) {
            const uint8_t* plane = &dat[(fed / BEATS) * PLANE_BYTES];
            uint32_t bits = 0;  // P / 8 bytes per beat, the first lowest
            for (int b = 0; b < P / 8; ++b) bits |= (uint32_t)plane[(fed % BEATS) * (P / 8) + b] << (8 * b);
            m.in_bits = bits;
            ++fed;
        }
        clock();
        ++cycle;
        if (m.out_valid) {
            if (!check()) return 1;
            ++got;
        }
        if (cycle > beats * 3 + 64) {
            std::fprintf(stderr, "the RTL stopped after %zu of %zu beats\n", got, beats);
            return 1;
        }
    }
    if (m.planes != planes) {
        std::fprintf(stderr, "the RTL counted %u planes, the recording %zu\n", m.planes, planes);
        return 1;
    }
    std::printf("planes=%zu events=%zu equal\n", planes, total);
    return total > 0 ? 0 : 1;
}
