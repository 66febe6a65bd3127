// spiv's static-light model at sensor rate: spike planes in, P pixels per
// clock; out, per pixel and plane, the innovation event it settles (+1: a
// spike its static light did not predict; -1: a predicted spike that did
// not come, `late` ticks earlier) and its new state. Bit-exact with
// spiv-core's `light::Light` (through the C ABI's `spiv_light_push`;
// fpga/tb/tb_light.cpp checks every event and every pixel's state after
// every plane).
//
// Per pixel the design keeps 78 bits, one word of 78 * P bits per P
// pixels, read, updated and written back once per plane (a simple
// dual-port RAM, one read and one write per clock):
//
//   [77:62] last spike tick mod 2^16   [61:46] period, 1/16 tick
//   [45:21] mean rate, 2^-24 spike/tick [20:12] ticks of short intervals
//   [11:4]  lead, 1/16 tick (signed)    [3] has spiked  [2:0] agreements
//
// (the core stores the same values in wider integers: a rate never passes
// 2^24, a short run 511, agreements 7). The rate's running mean divides by
// k = min(ticks seen, 256), the same for every pixel of a plane: a
// multiply by R(k) = ceil(2^33 / k) from a ROM and a shift, exact for
// every numerator below 2^25 (x * (R k - 2^33) < 2^33). The dither of the
// period's learning, the top bits of t * 0x9E3779B9, is the same for every
// pixel of a plane too, and worked out once per plane.
//
// Latency 5 clocks from in_bits to out_valid. in_valid may pause; planes
// are W * H / P beats back to back in stored pixel order (pixel y * W + x
// in lane x % P of beat (y * W + x) / P), the first getting tick `first`.

module spiv_light #(
    parameter integer W = 128,
    parameter integer H = 64,
    parameter integer P = 8       // pixels per clock; W * H % P == 0
) (
    input  logic               clk,
    input  logic               rst,
    input  logic [31:0]        first,     // tick of the first plane
    // spike planes in
    input  logic               in_valid,
    input  logic [P-1:0]       in_bits,
    // per beat: the pixels' events and new states
    output logic               out_valid,
    output logic [31:0]        out_tick,  // the plane's tick
    output logic [P-1:0]       out_plus,  // +1 at out_tick
    output logic [P-1:0]       out_minus, // -1 at out_tick - late
    output logic [5*P-1:0]     out_late,  // ticks, per lane
    output logic [78*P-1:0]    out_state, // registered with out_valid
    // planes taken so far
    output logic [31:0]        planes
);
    localparam integer BEATS = W * H / P;
    localparam integer ABITS = $clog2(BEATS);
    localparam integer SB = 78;          // state bits per pixel
    localparam integer RS = 33;          // the rate division's shift

    initial begin
        if (BEATS < 5 || W * H % P != 0)
            $fatal(1, "spiv_light: W*H must be at least five beats of P pixels");
    end

    // ---- reciprocals: R(k) = ceil(2^33 / k), k in 1..256 ----------------
    logic [RS:0] recip [0:256];
    initial begin
        recip[0] = 0;
        for (int i = 1; i <= 256; i = i + 1)
            recip[i] = (RS+1)'(((64'd1 << RS) + 64'(i) - 64'd1) / 64'(i));
    end

    // ---- per-pixel state ------------------------------------------------
    logic [SB*P-1:0] mem [0:BEATS-1];
    initial begin
        for (int i = 0; i < BEATS; i = i + 1) mem[i] = '0;
    end

    // ---- the plane being taken: its tick, k, R(k), the dither hash ------
    logic [ABITS-1:0] beat;
    logic [31:0]      tick, seen;
    logic [31:0]      hash;       // (tick mod 2^16) * 0x9E3779B9 mod 2^32
    localparam logic [31:0] GOLD = 32'h9E37_79B9;

    wire [31:0] seen1 = (seen == 32'hFFFF_FFFF) ? seen : seen + 32'd1;
    wire [8:0]  k1 = (seen1 >= 32'd256) ? 9'd256 : seen1[8:0];

    always_ff @(posedge clk) begin
        if (rst) begin
            beat <= '0;
            tick <= first;
            seen <= '0;
            hash <= {16'd0, first[15:0]} * GOLD;
        end else if (in_valid) begin
            // The plane starts: it is one more tick seen.
            if (beat == '0) seen <= seen1;
            if (beat == ABITS'(BEATS - 1)) begin
                beat <= '0;
                tick <= tick + 32'd1;
                hash <= (tick[15:0] == 16'hFFFF) ? 32'd0 : hash + GOLD;
            end else begin
                beat <= beat + 1'b1;
            end
        end
    end
    wire plane_start = in_valid && beat == '0;

    // ---- stage 1: the state word read (block RAM) -----------------------
    logic             s1_valid;
    logic [ABITS-1:0] s1_beat;
    logic [P-1:0]     s1_bits;
    logic [SB*P-1:0]  s1_state;
    logic [31:0]      s1_tick, s1_hash;
    logic [8:0]       s1_k;
    logic [RS:0]      s1_r;
    always_ff @(posedge clk) begin
        s1_valid <= in_valid && !rst;
        s1_beat <= beat;
        s1_bits <= in_bits;
        s1_state <= mem[beat];
        // The plane's k and R(k) travel with its beats.
        if (plane_start) begin
            s1_tick <= tick;
            s1_hash <= hash;
            s1_k <= k1;
            s1_r <= recip[k1];
        end
    end

    // ---- stage 2: the word registered -----------------------------------
    logic             s2_valid;
    logic [ABITS-1:0] s2_beat;
    logic [P-1:0]     s2_bits;
    logic [SB*P-1:0]  s2_state;
    logic [16*P-1:0]  s2_since;   // ticks since each pixel's last spike, mod 2^16
    logic [31:0]      s2_tick, s2_hash;
    logic [8:0]       s2_k;
    logic [RS:0]      s2_r;
    always_ff @(posedge clk) begin
        s2_valid <= s1_valid;
        s2_beat <= s1_beat;
        s2_bits <= s1_bits;
        s2_state <= s1_state;
        for (int l = 0; l < P; l = l + 1)
            s2_since[16*l +: 16] <= s1_tick[15:0] - s1_state[SB*l + 62 +: 16];
        s2_tick <= s1_tick;
        s2_hash <= s1_hash;
        s2_k <= s1_k;
        s2_r <= s1_r;
    end

    // ---- stages 3 to 5: each pixel's update; written back ---------------
    logic             s3_valid, s4_valid;
    logic [ABITS-1:0] s3_beat, s4_beat;
    logic [31:0]      s3_tick, s4_tick;
    logic [SB*P-1:0]  s4_state;   // the new states, as stage 4 left them
    always_ff @(posedge clk) begin
        s3_valid <= s2_valid;
        s3_beat <= s2_beat;
        s3_tick <= s2_tick;
        s4_valid <= s3_valid;
        s4_beat <= s3_beat;
        s4_tick <= s3_tick;
        out_valid <= s4_valid;
        out_tick <= s4_tick;
        out_state <= s4_state;
        if (s4_valid) mem[s4_beat] <= s4_state;
    end

    // tolerance(p) = min(1 + p/16, 16); early_tolerance(p) = min(p/16, 16)
    function automatic logic [4:0] late_of(input logic [15:0] p);
        logic [15:0] q;
        q = 16'd1 + (p >> 4);
        late_of = (q > 16'd16) ? 5'd16 : q[4:0];
    endfunction
    function automatic logic [4:0] early_of(input logic [15:0] p);
        logic [15:0] q;
        q = p >> 4;
        early_of = (q > 16'd16) ? 5'd16 : q[4:0];
    endfunction
    // settled_shift(per) = 4 + max(0, 4 - floor(log2(max(per >> 4, 1))))
    function automatic logic [3:0] settled_of(input logic [15:0] per);
        logic [11:0] whole;
        whole = per[15:4];
        if (whole >= 12'd16) settled_of = 4'd4;
        else if (whole >= 12'd8) settled_of = 4'd5;
        else if (whole >= 12'd4) settled_of = 4'd6;
        else if (whole >= 12'd2) settled_of = 4'd7;
        else settled_of = 4'd8;
    endfunction

    genvar g;
    generate
        for (g = 0; g < P; g = g + 1) begin : lane
            // The pixel's state as read.
            wire [15:0] last   = s2_state[SB*g + 62 +: 16];
            wire [15:0] period = s2_state[SB*g + 46 +: 16];
            wire [24:0] rate   = s2_state[SB*g + 21 +: 25];
            wire [8:0]  short_ = s2_state[SB*g + 12 +: 9];
            wire signed [7:0] lead = s2_state[SB*g + 4 +: 8];
            wire        spiked = s2_state[SB*g + 3];
            wire [2:0]  count  = s2_state[SB*g +: 3];
            wire        spike  = s2_bits[g];

            // Stage 3: the rate's step x = |d| + floor(k / 2); the
            // update's comparisons and operands, registered.
            logic        a_neg, a_zero;
            logic [24:0] a_rate, a_x;
            logic [RS:0] a_r;
            logic        a_spike, a_spiked, a_in_window, a_minus;
            logic        a_far, a_init, a_agrees;
            logic [2:0]  a_count;
            logic [15:0] a_period, a_last, a_t16, a_iv;
            logic [8:0]  a_short;
            logic [16:0] a_run;
            logic signed [7:0] a_lead;
            logic [4:0]  a_late;
            logic        a_short_p;               // p < 8: the lead is kept
            logic signed [31:0] a_acc, a_thr, a_d;
            logic [3:0]  a_shift;
            logic [31:0] a_u;

            always_ff @(posedge clk) begin
                logic [24:0] mag;
                logic [24:0] x;
                // d = (spike ? 2^24 : 0) - rate; its magnitude and sign.
                mag = spike ? 25'h100_0000 - rate : rate;
                a_neg <= !spike && rate != 0;
                a_zero <= mag == 0;
                x = mag + {16'd0, s2_k[8:1]};
                a_x <= x;
                a_r <= s2_r;
                a_rate <= rate;
            end

            always_ff @(posedge clk) begin
                logic [15:0] since, p, iv;
                logic [4:0]  late, early;
                logic        periodic;
                logic signed [31:0] d, per32;
                logic [19:0] iv5;
                logic [3:0]  shift;
                since = s2_since[16*g +: 16];
                per32 = $signed({16'd0, period});
                p = (period >> 4) == 16'd0 ? 16'd1 : (period >> 4);
                late = late_of(p);
                early = early_of(p);
                periodic = spiked && count >= 3'd2;
                iv = {since[11:0], 4'd0};
                d = $signed({16'd0, iv}) - per32;
                iv5 = {2'd0, iv, 2'd0} + {4'd0, iv};
                shift = (count >= 3'd2) ? settled_of(period) : 4'd1;
                a_spike <= spike;
                a_spiked <= spiked;
                // The predicted window: p - early ..= p + late ticks
                // (p <= 4095: p + late never saturates 16 bits).
                a_in_window <= periodic
                    && ({1'b0, since} + {12'd0, early} >= {1'b0, p})
                    && (since <= p + {11'd0, late});
                a_minus <= periodic && since == p + {11'd0, late};
                a_short_p <= p < 16'd8;
                // ahead()'s sum before its leak.
                a_acc <= $signed({{24{lead[7]}}, lead}) + $signed({12'd0, since, 4'd0}) - per32;
                a_thr <= 32'sd24 + $signed({23'd0, early, 4'd0});
                // learn()'s cases: past the longest period, a first
                // interval, an agreeing one: |d| <= max(period / 5, 16)
                // with d = iv - period, without a division or |d|:
                // |d| <= 16 iff iv + 16 >= period and iv <= period + 16;
                // |d| <= floor(period / 5) iff 5 |d| <= period iff
                // 5 iv <= 6 period and 5 iv >= 4 period.
                a_far <= since > 16'd4095;
                a_init <= count == 3'd0 || period == 16'd0;
                a_agrees <= ({1'b0, iv} + 17'd16 >= {1'b0, period}
                             && {1'b0, iv} <= {1'b0, period} + 17'd16)
                         || (iv5 <= {2'd0, period, 2'd0} + {3'd0, period, 1'b0}
                             && iv5 >= {2'd0, period, 2'd0});
                a_d <= d;
                a_iv <= iv;
                a_shift <= shift;
                a_u <= s2_hash >> (6'd32 - {2'd0, shift});
                a_run <= {8'd0, short_} + {1'b0, since};
                a_count <= count;
                a_period <= period;
                a_last <= last;
                a_t16 <= s2_tick[15:0];
                a_short <= short_;
                a_lead <= lead;
                a_late <= late;
            end

            // Stage 4: the update; x times R(k) in two halves of R.
            logic        b_neg, b_zero;
            logic [24:0] b_rate;
            logic [41:0] b_lo, b_hi;    // x * R[16:0], x * R[33:17]
            logic [SB-1:0] b_rest;      // the state with the rate field 0
            logic        b_plus, b_minus;
            logic [4:0]  b_late;
            always_ff @(posedge clk) begin
                b_neg <= a_neg;
                b_zero <= a_zero;
                b_rate <= a_rate;
                b_lo <= {17'd0, a_x} * {25'd0, a_r[16:0]};
                b_hi <= {17'd0, a_x} * {25'd0, a_r[RS:17]};
                b_late <= a_late;
            end

            always_ff @(posedge clk) begin
                logic [15:0] per_n, last_n;
                logic        extra, spiked_n, minus;
                logic signed [7:0] lead_n;
                logic [8:0]  short_n;
                logic [2:0]  count_n;
                logic signed [31:0] acc, step;
                lead_n = a_lead;
                short_n = a_short;
                count_n = a_count;
                spiked_n = a_spiked;
                per_n = a_period;
                last_n = a_last;
                extra = 1'b0;
                minus = 1'b0;
                if (a_spike) begin
                    if (!a_in_window) begin
                        extra = 1'b1;
                        lead_n = 8'sd0;
                    end else if (a_short_p) begin
                        // ahead(): the lead gains the spike's deviation
                        // from the period and leaks an eighth.
                        acc = a_acc - (a_acc >>> 3);
                        extra = acc < -a_thr;
                        if (extra) acc = acc + $signed({16'd0, a_period});
                        lead_n = (acc > 32'sd127) ? 8'sd127
                               : (acc < -32'sd128) ? -8'sd128 : acc[7:0];
                    end else begin
                        lead_n = 8'sd0;
                    end
                    if (a_spiked) begin
                        // learn(): the period and agreements.
                        if (a_far) begin
                            per_n = 16'd0;
                            count_n = 3'd0;
                            short_n = 9'd0;
                        end else if (a_init) begin
                            per_n = a_iv;
                            count_n = 3'd1;
                            short_n = 9'd0;
                        end else if (a_agrees) begin
                            step = (a_d + $signed(a_u)) >>> a_shift;
                            per_n = a_period + step[15:0];
                            count_n = (a_count == 3'd7) ? 3'd7 : a_count + 3'd1;
                            short_n = 9'd0;
                        end else if (a_d < 0 && a_run < 17'd512) begin
                            short_n = a_run[8:0];
                        end else if (a_d > 0 && a_count > 3'd2) begin
                            count_n = a_count - 3'd2;
                        end else begin
                            per_n = a_iv;
                            count_n = 3'd1;
                            short_n = 9'd0;
                        end
                    end
                    last_n = a_t16;
                    spiked_n = 1'b1;
                end else if (a_minus) begin
                    minus = 1'b1;
                    count_n = a_count - 3'd1;
                end
                b_rest <= {last_n, per_n, 25'd0, short_n, lead_n, spiked_n, count_n};
                b_plus <= a_spike && extra;
                b_minus <= minus;
            end

            // Stage 5: the rate stepped by sign * floor(x / k); out.
            logic [24:0] q;
            logic [RS+25:0] prod;
            assign prod = {b_hi, 17'd0};
            assign q = b_zero ? 25'd0 : 25'((prod + {17'd0, b_lo}) >> RS);
            assign s4_state[SB*g +: SB] = b_rest
                | {32'd0, (b_neg ? b_rate - q : b_rate + q), 21'd0};
            always_ff @(posedge clk) begin
                out_plus[g] <= b_plus;
                out_minus[g] <= b_minus;
                out_late[5*g +: 5] <= b_late;
            end
        end
    endgenerate

    assign planes = tick - first;
endmodule
