// Verilator testbench of fpga/rtl/spiv_ring.sv: the events the light
// model settles (spiv-core's, through `spiv_light_push`) go into the RTL
// ring plane by plane, while a second, identical light model feeds the
// core's ring (`spiv_ring_push`). After every plane the RTL ring's first
// and next tick, stored, lost and evicted counts must equal the core's;
// every few planes, reads of several tick ranges (`spiv_ring_events`)
// must give the same events in the same order.
//
//   tb_ring FILE.dat | noise:N | burst:N | slow:N
//
// FILE.dat is W x H planes (set when verilated); noise:N is N planes of
// pixels spiking at random, half of them each tick (more events per tick
// than a small ring holds: ticks evicted, events lost); burst:N alternates
// quiet planes with planes where every pixel spikes; slow:N gives every
// pixel a period of 240 to 299 ticks with about one spike in four missing,
// so that predictions settle the longest tolerance, 16 ticks, late (a
// read that stops one tick short of b + 16 misses them).
//
// Prints `planes=N events=E late16=S reads=R read=K evicted=V lost=L
// equal` (S: events settled 16 ticks late) and
// exits 0, or names the first difference and exits 1.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "Vspiv_ring.h"
#include "core_light.h"
#include "read_file.h"
#include "verilated.h"

extern "C" {
#include "spiv_core.h"
}

#ifndef TB_W
#error "TB_W, TB_H, TB_CAPB and TB_DEPB must match the model"
#endif

static const int W = TB_W, H = TB_H, PX = W * H, PLANE_BYTES = PX / 8;
static const size_t CAP = (size_t)1 << TB_CAPB, DEPTH = ((size_t)1 << TB_DEPB) - 1;

struct Bench {
    Vspiv_ring m;
    std::vector<SpivEvent> got;
    bool done = false;
    void clock() {
        m.clk = 0;
        m.eval();
        m.clk = 1;
        m.eval();
        if (m.ev_valid) got.push_back(SpivEvent{m.ev_index, m.ev_tick, (int8_t)(m.ev_neg ? -1 : 1)});
        if (m.rd_done) done = true;
    }
};

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: tb_ring FILE.dat | noise:N | burst:N | slow:N\n");
        return 2;
    }
    std::vector<uint8_t> dat;
    uint64_t x = 0x2545F4914F6CDD1Dull;
    auto rnd = [&x]() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return x;
    };
    if (std::strncmp(argv[1], "noise:", 6) == 0) {
        dat.resize(std::strtoul(argv[1] + 6, nullptr, 10) * PLANE_BYTES);
        for (auto& b : dat) b = (uint8_t)(rnd() >> 24);
    } else if (std::strncmp(argv[1], "burst:", 6) == 0) {
        const size_t n = std::strtoul(argv[1] + 6, nullptr, 10);
        dat.assign(n * PLANE_BYTES, 0);
        for (size_t t = 0; t < n; t += 7)
            std::memset(&dat[t * PLANE_BYTES], 0xff, PLANE_BYTES);
    } else if (std::strncmp(argv[1], "slow:", 5) == 0) {
        // Every pixel on its own period of 240 to 299 ticks, skipping about
        // one spike in four: its predictions that do not come settle the
        // longest tolerance (16 ticks) late.
        const size_t n = std::strtoul(argv[1] + 5, nullptr, 10);
        dat.assign(n * PLANE_BYTES, 0);
        for (int p = 0; p < PX; ++p) {
            const size_t period = 240 + (size_t)(p * 7) % 60, phase = rnd() % period;
            for (size_t t = phase; t < n; t += period)
                if (rnd() % 4 != 0) dat[t * PLANE_BYTES + p / 8] |= (uint8_t)(1u << (p % 8));
        }
    } else {
        dat = read_file(argv[1]);
    }
    const size_t planes = dat.size() / PLANE_BYTES;
    if (planes == 0 || dat.size() % PLANE_BYTES != 0) {
        std::fprintf(stderr, "%s: not whole %dx%d planes\n", argv[1], W, H);
        return 2;
    }
    const uint32_t first = 1000;

    CoreLight core_light(W, H, first), rtl_light(W, H, first);
    std::vector<uint32_t> entries(CAP), starts(DEPTH + 1);
    SpivRing ring{entries.data(), CAP, starts.data(), DEPTH, 0, 0, 0, 0, 0};
    if (spiv_ring_init(&ring, first) != SPIV_OK) return 2;

    Bench b;
    b.m.first_tick = first;
    b.m.rst = 1;
    b.clock();
    b.clock();
    b.m.rst = 0;
    b.clock();

    std::vector<SpivEvent> evs(PX), want(CAP + 16);
    size_t events = 0, reads = 0, read = 0, late16 = 0;
    for (size_t p = 0; p < planes; ++p) {
        const uint8_t* plane = &dat[p * PLANE_BYTES];
        if (spiv_ring_push(&ring, &core_light.l, W, H, plane, PLANE_BYTES) != SPIV_OK) return 2;
        size_t n = 0;
        if (spiv_light_push(&rtl_light.l, W, H, plane, PLANE_BYTES, evs.data(), evs.size(), &n) !=
            SPIV_OK)
            return 2;
        events += n;
        for (size_t i = 0; i < n; ++i) late16 += first + (uint32_t)p - evs[i].tick >= 16;
        const uint32_t t = first + (uint32_t)p;
        b.m.in_open = 1;
        b.m.in_tick = t;
        b.clock();
        b.m.in_open = 0;
        for (size_t i = 0; i < n;) {
            b.m.in_valid = 1;
            b.m.in_index = evs[i].index;
            b.m.in_etick = evs[i].tick;
            b.m.in_neg = evs[i].sign < 0;
            const bool take = b.m.in_ready;
            b.clock();
            if (take) ++i;
        }
        b.m.in_valid = 0;
        // The last event may still wait for room.
        for (int k = 0; k < 4 * (int)DEPTH + 8 && !b.m.in_ready; ++k) b.clock();
        b.m.in_close = 1;
        b.clock();
        b.m.in_close = 0;
        b.clock();
        if (b.m.bad_tick || b.m.first != ring.first || b.m.next != ring.next ||
            b.m.stored != ring.stored || b.m.lost != ring.lost || b.m.evicted != ring.evicted) {
            std::fprintf(stderr,
                         "plane %zu: RTL first %u next %u stored %u lost %u evicted %u%s, core "
                         "%u %u %u %u %u\n",
                         p, b.m.first, b.m.next, b.m.stored, b.m.lost, b.m.evicted,
                         b.m.bad_tick ? " bad tick" : "", ring.first, ring.next, ring.stored,
                         ring.lost, ring.evicted);
            return 1;
        }
        if (p % 5 != 4 && p + 1 != planes) continue;
        // Reads: everything held and more, the last few ticks, one tick,
        // an empty range, and a range ending past the last tick.
        const uint32_t nx = ring.next;
        const uint32_t ranges[][2] = {
            {nx - (uint32_t)DEPTH - 20, nx + 5}, {nx - 6, nx - 1}, {nx - 3, nx - 2},
            {nx - 2, nx - 2}, {nx - 20, nx + 40}, {nx - 40, nx - 17}};
        for (const auto& r : ranges) {
            size_t nw = 0;
            if (spiv_ring_events(&ring, r[0], r[1], want.data(), want.size(), &nw) != SPIV_OK)
                return 2;
            b.got.clear();
            b.done = false;
            b.m.rd_a = r[0];
            b.m.rd_b = r[1];
            b.m.rd_start = 1;
            b.clock();
            b.m.rd_start = 0;
            for (size_t k = 0; k < 4 * CAP + 4 * DEPTH + 64 && !b.done; ++k) b.clock();
            if (!b.done || b.got.size() != nw) {
                std::fprintf(stderr, "plane %zu, ticks %u..%u: RTL %zu events%s, core %zu\n", p,
                             r[0], r[1], b.got.size(), b.done ? "" : " (unfinished)", nw);
                return 1;
            }
            for (size_t k = 0; k < nw; ++k) {
                const SpivEvent &g = b.got[k], &w = want[k];
                if (g.index != w.index || g.tick != w.tick || g.sign != w.sign) {
                    std::fprintf(stderr,
                                 "plane %zu, ticks %u..%u, event %zu: RTL %u@%u%+d, core %u@%u%+d\n",
                                 p, r[0], r[1], k, g.index, g.tick, g.sign, w.index, w.tick,
                                 w.sign);
                    return 1;
                }
            }
            ++reads;
            read += nw;
        }
    }
    std::printf("planes=%zu events=%zu late16=%zu reads=%zu read=%zu evicted=%u lost=%u equal\n",
                planes, events, late16, reads, read, ring.evicted, ring.lost);
    return 0;
}
