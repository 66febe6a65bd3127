// The live mode's frame pipeline, spike planes in, rung frames out: the
// static-light model (spiv_light.sv) settles each plane's events, P pixels
// per clock; they queue by beat and go into the event ring one per clock
// in pixel order (spiv_pair.sv, the ring chained to the rung frames); the
// rung frames read each pixel's static rate from a copy of the light
// model's rates and flags, written as its states stream out. Bit-exact
// with spiv-core's `rungs::EventRing::push` and `rungs::rung_frames`
// (fpga/tb/tb_live.cpp).
//
// Planes go in as spiv_light's do (in_valid may pause; in_ready low asks
// the source to pause, in time for the beats still in the light model's
// pipeline). A pair is asked for as spiv_pair's are, once the ring holds
// its ticks (`ring_next`).

module spiv_live #(
    parameter integer W = 128,
    parameter integer H = 64,
    parameter integer P = 8,      // pixels per clock into the light model
    parameter integer NR = 8,
    parameter integer NXB = 6,
    parameter integer NYB = 6,
    parameter integer CAPB = 16,
    parameter integer DEPB = 9,
    parameter integer FB = 4      // log2 of the beats queued
) (
    input  logic                 clk,
    input  logic                 rst,
    input  logic [31:0]          first_tick,
    // spike planes
    input  logic                 in_valid,
    output logic                 in_ready,
    input  logic [P-1:0]         in_bits,
    // the flow's nodes
    input  logic                 node_we,
    input  logic [NYB-1:0]       node_r,
    input  logic [NXB-1:0]       node_c,
    input  logic signed [15:0]   node_vx,
    input  logic signed [15:0]   node_vy,
    input  logic signed [15:0]   node_ax,
    input  logic signed [15:0]   node_ay,
    // the pair
    input  logic                 start,
    input  logic [31:0]          mid,
    input  logic [3:0]           nsep,
    input  logic [8*NR-1:0]      seps,
    input  logic [15:0]          nx,
    input  logic [15:0]          ny,
    input  logic signed [31:0]   x0,
    input  logic signed [31:0]   y0,
    input  logic [12:0]          pitch,
    input  logic [31:0]          ev_from,
    // the frames
    output logic                 out_valid,
    output logic [$clog2(W*H)-1:0] out_index,
    output logic [16*NR-1:0]     out_a,
    output logic [16*NR-1:0]     out_b,
    output logic                 busy,
    output logic                 done,
    output logic                 error,
    // where the ring stands
    output logic [31:0]          ring_first,
    output logic [31:0]          ring_next,
    output logic [31:0]          ring_stored,
    output logic [31:0]          ring_lost,
    output logic [31:0]          ring_evicted,
    output logic                 ring_bad_tick
);
    localparam integer PX = W * H;
    localparam integer BEATS = PX / P;
    localparam integer AB = $clog2(BEATS);
    localparam integer AW = $clog2(PX);
    localparam integer FD = 1 << FB;

    // ---- the light model --------------------------------------------------
    logic             l_valid;
    logic [31:0]      l_tick, l_planes;
    logic [P-1:0]     l_plus, l_minus;
    logic [5*P-1:0]   l_late;
    logic [78*P-1:0]  l_state;
    spiv_light #(.W(W), .H(H), .P(P)) light (
        .clk, .rst, .first(first_tick),
        .in_valid, .in_bits,
        .out_valid(l_valid), .out_tick(l_tick), .out_plus(l_plus), .out_minus(l_minus),
        .out_late(l_late), .out_state(l_state), .planes(l_planes)
    );

    // beats out of the light model, in order (their place in the plane)
    logic [AB-1:0] l_beat;
    always_ff @(posedge clk) begin
        if (rst) l_beat <= 0;
        else if (l_valid) l_beat <= (l_beat == AB'(BEATS - 1)) ? '0 : l_beat + 1;
    end

    // ---- the rates' copy: rate and flags per pixel, one word per beat ------
    // flags as the core keeps them: bit 7 has spiked, bits 0-3 agreements
    logic [32*P-1:0] rate_word [BEATS];
    logic [8*P-1:0]  flag_word [BEATS];
    logic [32*P-1:0] rates_in;
    logic [8*P-1:0]  flags_in;
    always_comb begin
        for (int l = 0; l < P; ++l) begin
            rates_in[32*l +: 32] = {7'b0, l_state[78*l + 21 +: 25]};
            flags_in[8*l +: 8] = {l_state[78*l + 3], 4'b0, l_state[78*l +: 3]};
        end
    end
    // The rung frames register rate_addr, take the word the next clock and
    // register it: the copy is read at that registered address, its
    // output (through the lane's choice) into that register alone.
    logic [AW-1:0]    rate_addr;
    logic [32*P-1:0]  rate_q;
    logic [8*P-1:0]   flag_q;
    logic [$clog2(P)-1:0] rate_lane;
    always_ff @(posedge clk) begin
        if (l_valid) begin
            rate_word[l_beat] <= rates_in;
            flag_word[l_beat] <= flags_in;
        end
    end
    always_comb begin
        rate_q = rate_word[AB'(rate_addr / AW'(P))];
        flag_q = flag_word[AB'(rate_addr / AW'(P))];
        rate_lane = $clog2(P)'(rate_addr % AW'(P));
    end

    // ---- beats queued for the ring ------------------------------------------
    logic [P-1:0]    q_plus [FD];
    logic [P-1:0]    q_minus [FD];
    logic [5*P-1:0]  q_late [FD];
    logic [31:0]     q_tick [FD];
    logic [AB-1:0]   q_beat [FD];
    logic [FB:0]     q_head, q_tail, q_count;
    logic [FB:0]     in_flight;  // beats in the light model's pipeline
    always_comb q_count = q_tail - q_head;
    // room for every beat that may still come out of the light model
    assign in_ready = 32'(q_count) + 32'(in_flight) + 1 < FD;
    always_ff @(posedge clk) begin
        if (rst) begin
            in_flight <= 0;
        end else begin
            in_flight <= in_flight + (FB + 1)'(in_valid) - (FB + 1)'(l_valid);
        end
    end

    // ---- the head beat's events, one per clock, into the ring --------------
    typedef enum logic [1:0] {S_OPEN, S_EVENTS, S_CLOSE} sstate_t;
    sstate_t      ss;
    logic [P-1:0] left;          // the head beat's lanes still to send
    logic         head_loaded;
    logic         have_head;
    always_comb have_head = q_count != 0;

    // the lowest lane left
    logic [$clog2(P)-1:0] lane;
    logic                 any;
    always_comb begin
        lane = 0;
        any = 0;
        for (int l = P - 1; l >= 0; --l)
            if (left[l]) begin
                lane = $clog2(P)'(l);
                any = 1;
            end
    end

    logic        r_open, r_valid, r_ready, r_neg, r_close;
    logic [31:0] r_tick, r_etick;
    logic [25:0] r_index;
    logic [FB-1:0] hd;
    always_comb begin
        hd = q_head[FB-1:0];
        r_open = ss == S_OPEN && have_head && q_beat[hd] == 0;
        r_tick = q_tick[hd];
        r_valid = ss == S_EVENTS && head_loaded && any;
        r_index = 26'(32'(q_beat[hd]) * P + 32'(lane));
        r_neg = q_minus[hd][lane];
        r_etick = q_tick[hd] - (r_neg ? {27'b0, q_late[hd][5*lane +: 5]} : 32'd0);
        r_close = ss == S_CLOSE && r_ready;
    end

    always_ff @(posedge clk) begin
        if (rst) begin
            q_head <= 0;
            q_tail <= 0;
            ss <= S_OPEN;
            head_loaded <= 0;
        end else begin
            if (l_valid) begin
                q_plus[q_tail[FB-1:0]] <= l_plus;
                q_minus[q_tail[FB-1:0]] <= l_minus;
                q_late[q_tail[FB-1:0]] <= l_late;
                q_tick[q_tail[FB-1:0]] <= l_tick;
                q_beat[q_tail[FB-1:0]] <= l_beat;
                q_tail <= q_tail + 1;
            end
            case (ss)
                S_OPEN: if (r_open) begin
                    ss <= S_EVENTS;
                    head_loaded <= 0;
                end
                S_EVENTS: begin
                    if (!head_loaded) begin
                        if (have_head) begin
                            left <= q_plus[hd] | q_minus[hd];
                            head_loaded <= 1;
                        end
                    end else if (any) begin
                        if (r_ready) left[lane] <= 1'b0;
                    end else begin
                        // the beat is sent: the next, or the plane's end
                        q_head <= q_head + 1;
                        head_loaded <= 0;
                        if (q_beat[hd] == AB'(BEATS - 1)) ss <= S_CLOSE;
                    end
                end
                S_CLOSE: if (r_ready) ss <= S_OPEN;
                default: ss <= S_OPEN;
            endcase
        end
    end

    // ---- the ring and the rung frames -----------------------------------------
    logic [AW-1:0] pair_rate_addr;
    assign rate_addr = pair_rate_addr;
    spiv_pair #(.W(W), .H(H), .NR(NR), .NXB(NXB), .NYB(NYB), .CAPB(CAPB), .DEPB(DEPB)) pair (
        .clk, .rst, .first_tick,
        .in_open(r_open), .in_tick(r_tick), .in_valid(r_valid), .in_ready(r_ready),
        .in_index(r_index), .in_etick(r_etick), .in_neg(r_neg), .in_close(r_close),
        .node_we, .node_r, .node_c, .node_vx, .node_vy, .node_ax, .node_ay,
        .start, .mid, .nsep, .seps, .nx, .ny, .x0, .y0, .pitch, .ev_from,
        .rate_addr(pair_rate_addr), .rate_q24(rate_q[32*rate_lane +: 32]),
        .rate_flags(flag_q[8*rate_lane +: 8]),
        .out_valid, .out_index, .out_a, .out_b, .busy, .done, .error,
        .ring_first, .ring_next, .ring_stored, .ring_lost, .ring_evicted, .ring_bad_tick
    );
endmodule
