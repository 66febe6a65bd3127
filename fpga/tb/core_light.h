// spiv-core's static-light model over arrays the testbench owns (C ABI:
// spiv_light_init), for the testbenches that run the core's model beside
// the RTL.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <vector>

extern "C" {
#include "spiv_core.h"
}

// The model over w x h pixels, its first plane at tick `first`.
struct CoreLight {
    std::vector<uint16_t> last, period, short_run;
    std::vector<uint32_t> rate;
    std::vector<int8_t> lead;
    std::vector<uint8_t> flags;
    SpivLight l;
    CoreLight(int w, int h, uint32_t first)
        : last((size_t)w * h), period((size_t)w * h), short_run((size_t)w * h),
          rate((size_t)w * h), lead((size_t)w * h), flags((size_t)w * h) {
        l = SpivLight{last.data(), period.data(), rate.data(), short_run.data(),
                      lead.data(),  flags.data(),  (size_t)w * h, 0, 0};
        if (spiv_light_init(&l, (uint16_t)w, (uint16_t)h, first) != SPIV_OK) std::exit(2);
    }
    // `l` points into the arrays: not copied.
    CoreLight(const CoreLight&) = delete;
    CoreLight& operator=(const CoreLight&) = delete;
};
