// spiv's rung frames at sensor rate: the live mode's frames, made by
// scattering innovation events along the host's flow. Bit-exact with
// spiv-core's `rungs::rung_frames` (fpga/tb/tb_rungs.cpp holds every
// sample of every frame to `spiv_rung_frames` through the C ABI).
//
// For a pair with midpoint `mid` and separations s_k (k < nsep), frame A
// of rung k holds the events of ticks mid - s_k .. mid - 1 and frame B
// those of mid .. mid + s_k - 1, each event added (+-64, 1/64 spike,
// saturating) at the pixel the flow carries it to at its frame's centre;
// then every pixel's static rate over each 8-tick block of the window is
// taken off where the flow carries the pixel at the block's middle; then
// every sample is rounded to whole spikes and zeroed below the rung's
// floor. One lane per rung, each with its own frame RAMs (A and B), so an
// event goes into every frame that holds it in one clock; a rate block's
// path is the same in A and B (d2 = s - 2a - n in both), so one
// displacement serves both.
//
// The displacement of pixel (x, y) over d2 half ticks is the core's:
// bilinear node sums Sv, Sa (weights in 1/16 px), then
// floor((d2 * Sv * 64 + d2^2 * Sa + 2^(2p+18)) / 2^(2p+19)) clamped to
// i16, where pitch = 2^p (1/16 px). The core divides by pitch^2 * 2^19 for
// any pitch; this design takes the power-of-two pitches the host's grids
// use (16..4096 in 1/16 px: 1..256 px) and refuses others (`error`), so
// the division is a shift. The node sums are separable (along x, then
// y): the same integers as the core's sum over the four products. Each
// column's and row's place between nodes is worked out once per pair
// into two small tables (max(W, H) + 4 clocks after `start`).
//
// Sequence: write the flow's nodes (node_we, while idle), pulse `start`
// with the pair's configuration held steady until `done`; once ev_ready
// rises, feed the
// events of the ring in its order (ev_valid while ev_ready; the ring's
// events of other ticks are ignored), then pulse `ev_end`; the design
// reads every pixel's light state, one pixel per clock (rate_addr;
// rate_q24 and rate_flags the next clock, as from a block RAM; the design
// registers them, and the rate it works out of them, before it decides:
// the RAM's output drives no logic but that register), and takes off the static rates of the pixels that have one, one block per clock;
// then it streams frames A and B of every lane side by side, pixel by
// pixel, out_valid high, clearing its RAMs as it goes; then `done` (with
// `error` when the configuration was refused and nothing was made).

module spiv_rungs #(
    parameter integer W = 128,
    parameter integer H = 64,
    parameter integer NR = 8,     // lanes: most rungs per pair (<= 8)
    parameter integer NXB = 6,    // node grid up to 2^NXB across
    parameter integer NYB = 6,    // and 2^NYB down
    localparam integer AW = $clog2(W * H)
) (
    input  logic                 clk,
    input  logic                 rst,
    // flow nodes, written while idle
    input  logic                 node_we,
    input  logic [NYB-1:0]       node_r,
    input  logic [NXB-1:0]       node_c,
    input  logic signed [15:0]   node_vx,  // Q12 px per tick
    input  logic signed [15:0]   node_vy,
    input  logic signed [15:0]   node_ax,  // Q16 px per tick^2
    input  logic signed [15:0]   node_ay,
    // the pair, held from start to done
    input  logic                 start,
    input  logic [31:0]          mid,
    input  logic [3:0]           nsep,
    input  logic [8*NR-1:0]      seps,     // ticks, lane k in [8k+7:8k]
    input  logic [15:0]          nx,       // nodes across (0: no motion)
    input  logic [15:0]          ny,
    input  logic signed [31:0]   x0,       // 1/16 px
    input  logic signed [31:0]   y0,
    input  logic [12:0]          pitch,    // 1/16 px, a power of two
    // events, in the ring's order
    output logic                 ev_ready,
    input  logic                 ev_valid,
    input  logic [31:0]          ev_index, // stored pixel
    input  logic [31:0]          ev_tick,
    input  logic                 ev_neg,   // -1 event
    input  logic                 ev_end,
    // the light model's state, one pixel per read
    output logic [AW-1:0]        rate_addr,
    input  logic [31:0]          rate_q24, // mean rate, 2^-24 spike per tick
    input  logic [7:0]           rate_flags,
    // frames out
    output logic                 out_valid,
    output logic [AW-1:0]        out_index,
    output logic [16*NR-1:0]     out_a,    // lane k's frame A in [16k+15:16k]
    output logic [16*NR-1:0]     out_b,
    output logic                 busy,
    output logic                 done,
    output logic                 error
);
    localparam integer PX = W * H;
    localparam integer NA = NYB - 1 + NXB - 1;   // node bank address bits
    localparam integer DEPTH = 24;               // clocks an op takes, and more
    localparam integer TN = (W > H) ? W : H;     // table entries to build
    // index -> row: floor(i * RW / 2^K) = floor(i / W) for every i < 2^AW
    // (exact when 2^AW * W < 2^K).
    localparam integer WB = $clog2(W + 1);
    localparam integer K = AW + WB + 1;
    localparam logic [63:0] RW = ((64'd1 << K) + 64'(W) - 64'd1) / 64'(W);
    localparam integer RB = AW + 3;              // bits of RW (< 2^(AW+2) + 1)
    localparam integer XB = (W > 2) ? $clog2(W) : 1;
    localparam integer YB = (H > 2) ? $clog2(H) : 1;

    initial begin
        if (NR < 1 || NR > 8 || PX < 2 || W > 65535 || H > 65535 || K > 60 || NXB > 15 || NYB > 15)
            $fatal(1, "spiv_rungs: 1..8 lanes, a frame of at most 2^(60 - log2 W) pixels");
    end

    // ---- the pair's configuration, checked at start -----------------------
    typedef enum logic [3:0] {IDLE, TABLES, EVENTS, RSCAN, RPREP, ROPS, DRAIN, OUT} phase_t;
    phase_t phase;
    logic [7:0]  sep [NR];
    logic [NR-1:0] act;
    logic [5:0]  blocks [NR];   // ceil(s / 8), at most 32
    logic [3:0]  n_last [NR];   // ticks of the last block, 1..8
    logic [5:0]  most_blocks;
    logic [2:0]  floor_spikes [NR];
    logic        still;
    logic [3:0]  ps;             // pitch = 2^ps
    logic [15:0] cnx, cny;
    logic signed [31:0] cx0, cy0;
    logic [31:0] cmid;

    // Whether `pitch` is 2^p, 4 <= p <= 12; p.
    function automatic logic [4:0] log2_pitch(input logic [12:0] v);
        log2_pitch = 5'd31;
        for (int i = 4; i <= 12; i++)
            if (v == 13'(1 << i)) log2_pitch = 5'(i);
    endfunction

    // ---- node RAM: four banks by (row, column) parity ----------------------
    logic [63:0] nodes [4][1 << NA];
    always_ff @(posedge clk) begin
        if (node_we && phase == IDLE)
            nodes[{node_r[0], node_c[0]}][{node_r[NYB-1:1], node_c[NXB-1:1]}] <=
                {node_ay, node_ax, node_vy, node_vx};
    end

    // ---- the axis tables: column x -> (c0, wx0, wx1), row y likewise -------
    // axis(p): q = clamp(16 p - first, -pitch, n pitch); i = clamp(q >> p,
    // 0, n - 2); f = q - i pitch; weights (pitch - f, f); one node: (0,
    // pitch, 0). Three stages per entry, one entry of each table per clock.
    logic [15:0]        col_i [W], row_i [H];
    logic signed [15:0] col_w0 [W], col_w1 [W], row_w0 [H], row_w1 [H];
    logic [15:0]        tb_at;                       // entry being started
    logic               t1_v, t2_v;
    logic [15:0]        t1_at, t2_at;
    logic signed [35:0] t1_qx, t1_qy, t2_qx, t2_qy;
    logic signed [35:0] t2_ix, t2_iy;
    // One axis, one stage each: the clamped coordinate of pixel p, the
    // node below it, the entry {i, w0, w1}.
    // The bounds -pitch and n pitch are the pair's: registered at start.
    logic signed [35:0] q_lo, q_hix, q_hiy;
    function automatic logic signed [35:0] clamped(input logic [15:0] p, input logic signed [31:0] first,
                                                   input logic signed [35:0] lo, input logic signed [35:0] hi);
        logic signed [35:0] q;
        q = $signed({16'b0, p, 4'b0}) - 36'(first);
        clamped = (q < lo) ? lo : (q > hi) ? hi : q;
    endfunction
    function automatic logic signed [35:0] below(input logic signed [35:0] q, input logic [15:0] n,
                                                 input logic [3:0] sh);
        logic signed [35:0] i;
        i = q >>> sh;
        if (i > $signed({20'b0, n}) - 36'sd2) i = $signed({20'b0, n}) - 36'sd2;
        below = (i < 36'sd0) ? 36'sd0 : i;
    endfunction
    function automatic logic [47:0] entry(input logic signed [35:0] q, input logic signed [35:0] i,
                                          input logic [15:0] n, input logic [3:0] sh);
        logic signed [15:0] f;
        f = 16'(q - (i <<< sh));
        entry = (n < 16'd2) ? {16'd0, 16'sd1 <<< sh, 16'sd0} : {i[15:0], (16'sd1 <<< sh) - f, f};
    endfunction

    always_ff @(posedge clk) begin
        logic [47:0] ec, er;
        t1_qx <= clamped(tb_at, cx0, q_lo, q_hix);
        t1_qy <= clamped(tb_at, cy0, q_lo, q_hiy);
        t1_v <= phase == TABLES && 32'(tb_at) < TN;
        t1_at <= tb_at;
        t2_ix <= below(t1_qx, cnx, ps);
        t2_iy <= below(t1_qy, cny, ps);
        t2_qx <= t1_qx;
        t2_qy <= t1_qy;
        t2_v <= t1_v;
        t2_at <= t1_at;
        ec = entry(t2_qx, t2_ix, cnx, ps);
        er = entry(t2_qy, t2_iy, cny, ps);
        if (t2_v && 32'(t2_at) < W) begin
            col_i[XB'(t2_at)] <= ec[47:32];
            col_w0[XB'(t2_at)] <= ec[31:16];
            col_w1[XB'(t2_at)] <= ec[15:0];
        end
        if (t2_v && 32'(t2_at) < H) begin
            row_i[YB'(t2_at)] <= er[47:32];
            row_w0[YB'(t2_at)] <= er[31:16];
            row_w1[YB'(t2_at)] <= er[15:0];
        end
    end

    // ---- events in: two stages to the pixel's row and column ---------------
    logic               e1_v, e2_v;
    logic [AW-1:0]      e1_idx;
    logic [31:0]        e1_tick;
    logic signed [33:0] e2_da;          // mid - tick
    logic               e1_neg, e2_neg;
    logic [AW+RB-1:0]   e1_prod;
    logic [15:0]        e2_x, e2_y;
    wire  [AW+RB-1:0]   e1_row = e1_prod >> K;
    always_ff @(posedge clk) begin
        e1_v <= phase == EVENTS && ev_valid;
        e1_idx <= AW'(ev_index);
        e1_tick <= ev_tick;
        e1_neg <= ev_neg;
        e1_prod <= (AW+RB)'(AW'(ev_index)) * (AW+RB)'(RW);
        e2_v <= e1_v;
        e2_y <= 16'(e1_row);
        e2_x <= 16'(32'(e1_idx) - 32'(e1_row) * 32'(W));
        e2_da <= $signed({2'b0, cmid}) - $signed({2'b0, e1_tick});
        e2_neg <= e1_neg;
    end
    wire signed [33:0] ev_da = e2_da;

    // ---- op issue: one event, or one rate block of one pixel --------------
    logic               op_v;
    logic [15:0]        op_x, op_y;
    logic [NR-1:0]      op_ea, op_eb;   // into frame A, frame B
    logic signed [9:0]  op_d2 [NR];
    logic signed [15:0] op_delta [NR];

    // rates: the next pixel to read, the pixel whose state arrives, the
    // pixel whose blocks go out, its rate, the block
    logic [31:0]   pix;
    logic [15:0]   px_x, px_y;
    // reads issued (rs), their state registered (rm), its rate worked out
    // (rq)
    logic          rs_v, rm_v, rq_v;
    logic [31:0]   rs_pix, rm_pix, rq_pix;
    logic [15:0]   rs_x, rs_y, rm_x, rm_y, rq_x, rq_y;
    logic [31:0]   rate_r;          // the state, registered after the RAM
    logic [7:0]    flags_r;
    logic [15:0]   cur_x, cur_y;
    logic [15:0]   r16;
    logic [5:0]    blk;
    // rate_samples(r, n) = (r * n * 64 + 2^15) >> 16 (at most 512): of a
    // whole block, and of each lane's last
    logic signed [15:0] sub8, sub_last [NR];
    always_ff @(posedge clk) begin
        rate_r <= rate_q24;
        flags_r <= rate_flags;
    end
    wire  [31:0]   rate_rounded = (rate_r + 32'd128) >> 8;
    wire           periodic = flags_r[7] && flags_r[3:0] >= 4'd2;
    wire  [15:0]   rate_now = periodic ? 16'd0
                            : (rate_rounded > 32'hFFFF) ? 16'hFFFF : rate_rounded[15:0];
    logic [15:0]   rate_now_r;
    always_ff @(posedge clk) rate_now_r <= rate_now;

    // per lane: the event's frame and d2; a rate block's d2 and samples
    logic               ln_in_a [NR], ln_in_b [NR], ln_blk_on [NR];
    logic signed [9:0]  ln_ev_d2 [NR], ln_rate_d2 [NR];
    logic signed [15:0] ln_rate_sub [NR];
    for (genvar k = 0; k < NR; k++) begin : lane_op
        wire signed [11:0] s12 = $signed({4'b0, sep[k]});
        wire signed [11:0] da = $signed(ev_da[11:0]);
        // A: mid - s <= t < mid (1 <= da <= s); B: mid <= t < mid + s.
        assign ln_in_a[k] = act[k] && ev_da >= 34'sd1 && ev_da <= $signed({26'b0, sep[k]});
        assign ln_in_b[k] = act[k] && ev_da <= 34'sd0 && -ev_da < $signed({26'b0, sep[k]});
        // d2 = centre2 - (2t + 1): 2 da - s - 1 (A), 2 da + s - 1 (B).
        wire signed [11:0] d2a = 12'sd2 * da - s12 - 12'sd1;
        wire signed [11:0] d2b = 12'sd2 * da + s12 - 12'sd1;
        assign ln_ev_d2[k] = ln_in_b[k] ? d2b[9:0] : d2a[9:0];
        // A rate block: a = 8 blk ticks in, n = min(8, s - a) (8 but in
        // the last block); d2 = s - 2a - n. Its samples, rate_samples(r,
        // n), were worked out for the pixel (RPREP).
        wire last = blk == blocks[k] - 6'd1;
        wire [8:0] rn = last ? 9'(n_last[k]) : 9'd8;
        wire signed [11:0] rd2 = s12 - $signed({1'b0, blk, 4'b0}) - $signed({3'b0, rn});
        assign ln_rate_d2[k] = rd2[9:0];
        assign ln_blk_on[k] = act[k] && 6'(blk) < blocks[k];
        assign ln_rate_sub[k] = -(last ? sub_last[k] : sub8);
    end

    always_comb begin
        op_v = 1'b0;
        op_x = '0;
        op_y = '0;
        op_ea = '0;
        op_eb = '0;
        for (int k = 0; k < NR; k++) begin
            op_d2[k] = '0;
            op_delta[k] = '0;
        end
        if (e2_v) begin
            op_v = 1'b1;
            op_x = e2_x;
            op_y = e2_y;
            for (int k = 0; k < NR; k++) begin
                op_ea[k] = ln_in_a[k];
                op_eb[k] = ln_in_b[k];
                op_d2[k] = ln_ev_d2[k];
                op_delta[k] = e2_neg ? -16'sd64 : 16'sd64;
            end
        end else if (phase == ROPS) begin
            op_v = 1'b1;
            op_x = cur_x;
            op_y = cur_y;
            for (int k = 0; k < NR; k++) begin
                op_ea[k] = ln_blk_on[k];
                op_eb[k] = ln_blk_on[k];
                op_d2[k] = ln_rate_d2[k];
                op_delta[k] = ln_rate_sub[k];
            end
        end
    end

    // The op's lane part travels with it: frames, d2, d2^2 (from s2 on),
    // delta.
    typedef struct packed {
        logic [NR-1:0]        ea, eb;
        logic [NR*10-1:0]     d2;
        logic [NR*19-1:0]     dd;
        logic [NR*16-1:0]     delta;
    } lanes_t;
    lanes_t op_l;
    always_comb begin
        op_l.ea = op_v ? op_ea : '0;
        op_l.eb = op_v ? op_eb : '0;
        op_l.dd = '0;
        for (int k = 0; k < NR; k++) begin
            op_l.d2[10*k +: 10] = op_d2[k];
            op_l.delta[16*k +: 16] = op_delta[k];
        end
    end

    // ---- s1: the pixel's column and row entries ------------------------------
    logic               s1_v;
    logic [15:0]        s1_x, s1_y;
    logic [NXB-1:0]     s1_c0;
    logic [NYB-1:0]     s1_r0;
    logic signed [15:0] s1_wx0, s1_wx1, s1_wy0, s1_wy1;
    lanes_t             s1_l;
    always_ff @(posedge clk) begin
        s1_c0 <= NXB'(col_i[XB'(op_x)]);
        s1_wx0 <= col_w0[XB'(op_x)];
        s1_wx1 <= col_w1[XB'(op_x)];
        s1_r0 <= NYB'(row_i[YB'(op_y)]);
        s1_wy0 <= row_w0[YB'(op_y)];
        s1_wy1 <= row_w1[YB'(op_y)];
        s1_v <= op_v;
        s1_x <= op_x;
        s1_y <= op_y;
        s1_l <= op_l;
    end

    // ---- s2: the four nodes read, one per bank --------------------------------
    logic               s2_v;
    logic [15:0]        s2_x, s2_y;
    logic               s2_rp, s2_cp;   // parity of r0 and c0
    logic [63:0]        s2_q [4];
    logic signed [15:0] s2_wx0, s2_wx1, s2_wy0, s2_wy1;
    lanes_t             s2_l;
    wire [NYB-1:0] s1_r1 = s1_r0 + 1'b1;
    wire [NXB-1:0] s1_c1 = s1_c0 + 1'b1;
    always_ff @(posedge clk) begin
        for (int bk = 0; bk < 4; bk++) begin
            logic [NYB-1:0] r;
            logic [NXB-1:0] c;
            r = (s1_r0[0] == bk[1]) ? s1_r0 : s1_r1;
            c = (s1_c0[0] == bk[0]) ? s1_c0 : s1_c1;
            s2_q[bk] <= nodes[bk][{r[NYB-1:1], c[NXB-1:1]}];
        end
        s2_v <= s1_v;
        s2_x <= s1_x;
        s2_y <= s1_y;
        s2_rp <= s1_r0[0];
        s2_cp <= s1_c0[0];
        {s2_wx0, s2_wx1, s2_wy0, s2_wy1} <= {s1_wx0, s1_wx1, s1_wy0, s1_wy1};
        s2_l <= s1_l;
        for (int k = 0; k < NR; k++) begin
            logic signed [9:0] d;
            d = s1_l.d2[10*k +: 10];
            s2_l.dd[19*k +: 19] <= 19'(d * d);
        end
    end

    // ---- s3: products along x; s4: per node row; s5: products along y; s6:
    // ---- the node sums Sv, Sa (weight pitch^2) --------------------------------
    // s2t: the taps from the banks: tap (r0 + dr, c0 + dc) is bank
    // {r0[0] ^ dr, c0[0] ^ dc}
    logic [63:0]        t00, t01, t10, t11;
    logic               st_v;
    logic [15:0]        st_x, st_y;
    logic signed [15:0] st_wx0, st_wx1, st_wy0, st_wy1;
    lanes_t             st_l;
    always_ff @(posedge clk) begin
        t00 <= s2_q[{s2_rp, s2_cp}];
        t01 <= s2_q[{s2_rp, ~s2_cp}];
        t10 <= s2_q[{~s2_rp, s2_cp}];
        t11 <= s2_q[{~s2_rp, ~s2_cp}];
        {st_v, st_x, st_y, st_l} <= {s2_v, s2_x, s2_y, s2_l};
        {st_wx0, st_wx1, st_wy0, st_wy1} <= {s2_wx0, s2_wx1, s2_wy0, s2_wy1};
    end
    logic               s3_v;
    logic [15:0]        s3_x, s3_y;
    logic signed [31:0] s3_p [4][4];    // field, tap
    logic signed [15:0] s3_wy0, s3_wy1;
    lanes_t             s3_l;
    always_ff @(posedge clk) begin
        for (int fd = 0; fd < 4; fd++) begin
            s3_p[fd][0] <= $signed(t00[16*fd +: 16]) * st_wx0;
            s3_p[fd][1] <= $signed(t01[16*fd +: 16]) * st_wx1;
            s3_p[fd][2] <= $signed(t10[16*fd +: 16]) * st_wx0;
            s3_p[fd][3] <= $signed(t11[16*fd +: 16]) * st_wx1;
        end
        s3_v <= st_v;
        s3_x <= st_x;
        s3_y <= st_y;
        {s3_wy0, s3_wy1} <= {st_wy0, st_wy1};
        s3_l <= st_l;
    end

    logic               s4_v;
    logic [15:0]        s4_x, s4_y;
    logic signed [31:0] s4_g0 [4], s4_g1 [4];  // per field: rows r0, r1
    logic signed [15:0] s4_wy0, s4_wy1;
    lanes_t             s4_l;
    always_ff @(posedge clk) begin
        for (int fd = 0; fd < 4; fd++) begin
            s4_g0[fd] <= s3_p[fd][0] + s3_p[fd][1];
            s4_g1[fd] <= s3_p[fd][2] + s3_p[fd][3];
        end
        s4_v <= s3_v;
        s4_x <= s3_x;
        s4_y <= s3_y;
        {s4_wy0, s4_wy1} <= {s3_wy0, s3_wy1};
        s4_l <= s3_l;
    end

    logic               s5_v;
    logic [15:0]        s5_x, s5_y;
    logic signed [47:0] s5_p0 [4], s5_p1 [4];
    lanes_t             s5_l;
    always_ff @(posedge clk) begin
        for (int fd = 0; fd < 4; fd++) begin
            s5_p0[fd] <= 48'(s4_g0[fd]) * 48'(s4_wy0);
            s5_p1[fd] <= 48'(s4_g1[fd]) * 48'(s4_wy1);
        end
        s5_v <= s4_v;
        s5_x <= s4_x;
        s5_y <= s4_y;
        s5_l <= s4_l;
    end

    logic               s6_v;
    logic [15:0]        s6_x, s6_y;
    logic signed [47:0] s6_s [4];       // vx, vy, ax, ay
    lanes_t             s6_l;
    always_ff @(posedge clk) begin
        for (int fd = 0; fd < 4; fd++)
            s6_s[fd] <= still ? 48'sd0 : s5_p0[fd] + s5_p1[fd];
        s6_v <= s5_v;
        s6_x <= s5_x;
        s6_y <= s5_y;
        s6_l <= s5_l;
    end

    // ---- per lane: s7 d2 and d2^2 times the sums' 12-bit pieces (S = P3
    // ---- 2^36 + P2 2^24 + P1 2^12 + P0: one 18x18 multiplier each), s7b
    // ---- the halves (S = Shi 2^24 + Slo), s8 the products, s9 num = 64 d2 Sv
    // ---- + d2^2 Sa + 2^(s-1), s10 num >> s clamped (s = 2p + 19), s11 the
    // ---- target pixel, if in the image -----------------------------------------
    logic               s7_v, s7b_v, s8_v, s9_v, s10_v;
    logic [15:0]        s7_x, s7_y, s7b_x, s7b_y, s8_x, s8_y, s9_x, s9_y, s10_x, s10_y;
    lanes_t             s7_l, s7b_l, s8_l, s9_l, s10_l;
    logic signed [22:0] s7_vp [NR][2][4];                 // d2 x Pi, for vx, vy
    logic signed [30:0] s7_ap [NR][2][4];                 // d2^2 x Pi, for ax, ay
    logic signed [35:0] s7_vl [NR][2], s7_vh [NR][2];   // d2 x Slo, d2 x Shi, for vx, vy
    logic signed [43:0] s7_al [NR][2], s7_ah [NR][2];   // d2^2 x Slo, d2^2 x Shi, for ax, ay
    logic signed [65:0] s8_v2 [NR][2], s8_a2 [NR][2];
    logic signed [65:0] s9_num [NR][2];
    logic signed [15:0] s10_d [NR][2];
    always_ff @(posedge clk) begin
        for (int k = 0; k < NR; k++) begin
            logic signed [9:0] d;
            logic signed [17:0] dd;     // at most 254^2 < 2^17
            d = s6_l.d2[10*k +: 10];
            dd = $signed(s6_l.dd[19*k +: 18]);
            for (int a = 0; a < 2; a++) begin
                for (int i = 0; i < 3; i++) begin
                    s7_vp[k][a][i] <= d * $signed({1'b0, s6_s[a][12*i +: 12]});
                    s7_ap[k][a][i] <= dd * $signed({1'b0, s6_s[2 + a][12*i +: 12]});
                end
                s7_vp[k][a][3] <= d * $signed(s6_s[a][47:36]);
                s7_ap[k][a][3] <= dd * $signed(s6_s[2 + a][47:36]);
            end
        end
        {s7_v, s7_x, s7_y, s7_l} <= {s6_v, s6_x, s6_y, s6_l};
        for (int k = 0; k < NR; k++)
            for (int a = 0; a < 2; a++) begin
                s7_vl[k][a] <= 36'(s7_vp[k][a][0]) + (36'(s7_vp[k][a][1]) <<< 12);
                s7_vh[k][a] <= 36'(s7_vp[k][a][2]) + (36'(s7_vp[k][a][3]) <<< 12);
                s7_al[k][a] <= 44'(s7_ap[k][a][0]) + (44'(s7_ap[k][a][1]) <<< 12);
                s7_ah[k][a] <= 44'(s7_ap[k][a][2]) + (44'(s7_ap[k][a][3]) <<< 12);
            end
        {s7b_v, s7b_x, s7b_y, s7b_l} <= {s7_v, s7_x, s7_y, s7_l};
        for (int k = 0; k < NR; k++)
            for (int a = 0; a < 2; a++) begin
                s8_v2[k][a] <= (66'(s7_vh[k][a]) <<< 30) + (66'(s7_vl[k][a]) <<< 6);
                s8_a2[k][a] <= (66'(s7_ah[k][a]) <<< 24) + 66'(s7_al[k][a]);
            end
        {s8_v, s8_x, s8_y, s8_l} <= {s7b_v, s7b_x, s7b_y, s7b_l};
        for (int k = 0; k < NR; k++)
            for (int a = 0; a < 2; a++)
                s9_num[k][a] <= s8_v2[k][a] + s8_a2[k][a] + (66'sd1 <<< (6'({ps, 1'b0}) + 6'd18));
        {s9_v, s9_x, s9_y, s9_l} <= {s8_v, s8_x, s8_y, s8_l};
        for (int k = 0; k < NR; k++)
            for (int a = 0; a < 2; a++) begin
                logic signed [65:0] q;
                q = s9_num[k][a] >>> (6'({ps, 1'b0}) + 6'd19);
                s10_d[k][a] <= (q > 66'sd32767) ? 16'sd32767 : (q < -66'sd32768) ? -16'sd32768 : q[15:0];
            end
        {s10_v, s10_x, s10_y, s10_l} <= {s9_v, s9_x, s9_y, s9_l};
    end

    logic [NR-1:0]      s11_ea, s11_eb;
    logic [AW-1:0]      s11_addr [NR];
    logic signed [15:0] s11_delta [NR];
    always_ff @(posedge clk) begin
        for (int k = 0; k < NR; k++) begin
            logic signed [17:0] tx, ty;
            logic in_image;
            tx = $signed({2'b0, s10_x}) + 18'(s10_d[k][0]);
            ty = $signed({2'b0, s10_y}) + 18'(s10_d[k][1]);
            in_image = s10_v && tx >= 0 && ty >= 0 && tx < $signed(18'(W)) && ty < $signed(18'(H));
            s11_ea[k] <= in_image && s10_l.ea[k];
            s11_eb[k] <= in_image && s10_l.eb[k];
            s11_addr[k] <= AW'(32'(ty[15:0]) * 32'(W) + 32'(tx[15:0]));
            s11_delta[k] <= s10_l.delta[16*k +: 16];
        end
    end

    // out phase: the samples read, A and B side by side
    logic          o_run;
    logic [AW-1:0] o_pix;
    logic          o1_v;
    logic [AW-1:0] o1_pix;

    function automatic logic signed [15:0] sat16(input logic signed [15:0] a, input logic signed [15:0] b);
        logic signed [16:0] s;
        s = 17'(a) + 17'(b);
        if (s > 17'sd32767) s = 17'sd32767;
        if (s < -17'sd32768) s = -17'sd32768;
        sat16 = s[15:0];
    endfunction

    // Rounded to whole spikes (half up), 0 below the floor (1/64 spike).
    function automatic logic signed [15:0] floored(input logic signed [15:0] v, input logic [2:0] fl);
        logic signed [16:0] up, whole;
        up = 17'(v) + 17'sd32;
        whole = up & ~17'sd63;
        if (whole > 17'sd32704) whole = 17'sd32704;
        floored = (whole >= $signed({8'b0, fl, 6'b0})) ? whole[15:0] : 16'sd0;
    endfunction

    // One frame RAM of a lane: the sample read at s12, the saturating
    // sum written back the next clock (the previous write forwarded when
    // it was to the same pixel), cleared as the out phase reads it.
    for (genvar k = 0; k < NR; k++) begin : lane
        for (genvar h = 0; h < 2; h++) begin : frame
            logic signed [15:0] mem [PX];
`ifndef SYNTHESIS
            // Block RAM comes up zeroed from the bitstream; the simulator's
            // is cleared here.
            initial for (int i = 0; i < PX; i++) mem[i] = '0;
`endif
            logic               en, fw_v;
            logic [AW-1:0]      addr, fw_addr;
            logic signed [15:0] delta, q, fw_val;
            wire [AW-1:0] rd = o_run ? o_pix : s11_addr[k];
            wire signed [15:0] q_eff = (fw_v && fw_addr == addr) ? fw_val : q;
            wire signed [15:0] nv = sat16(q_eff, delta);
            always_ff @(posedge clk) begin
                q <= mem[rd];
                en <= (h == 0 ? s11_ea[k] : s11_eb[k]) && !o_run;
                addr <= rd;
                delta <= s11_delta[k];
                if (o1_v) begin
                    mem[o1_pix] <= '0;
                end else if (en) begin
                    mem[addr] <= nv;
                end
                fw_v <= en && !o1_v;
                fw_addr <= addr;
                fw_val <= nv;
            end
            wire signed [15:0] out = (k < 32'(nsep)) ? floored(q, floor_spikes[k]) : 16'sd0;
            if (h == 0) begin : a
                assign out_a[16*k +: 16] = out;
            end else begin : b
                assign out_b[16*k +: 16] = out;
            end
        end
    end
    assign out_valid = o1_v;
    assign out_index = o1_pix;

    // ---- the sequence ---------------------------------------------------------
    logic [4:0] drain;
    assign ev_ready = phase == EVENTS;
    assign busy = phase != IDLE;
    always_ff @(posedge clk) begin
        done <= 1'b0;
        o1_v <= o_run;
        o1_pix <= o_pix;
        if (rst) begin
            phase <= IDLE;
            error <= 1'b0;
            o_run <= 1'b0;
            o1_v <= 1'b0;
        end else case (phase)
            IDLE: if (start) begin
                logic [4:0] p;
                logic [7:0] longest;
                logic bad;
                logic [5:0] mb;
                p = log2_pitch(pitch);
                longest = '0;
                mb = '0;
                bad = nsep > 4'(NR);
                for (int k = 0; k < NR; k++) begin
                    logic [7:0] s;
                    s = seps[8*k +: 8];
                    sep[k] <= s;
                    act[k] <= k < 32'(nsep);
                    blocks[k] <= 6'((9'(s) + 9'd7) >> 3);
                    n_last[k] <= 4'(9'(s) - 9'({6'((9'(s) + 9'd7) >> 3) - 6'd1, 3'b0}));
                    floor_spikes[k] <= 3'd1 + 3'(s >= 8'd36) + 3'(s >= 8'd100) + 3'(s >= 8'd196);
                    if (k < 32'(nsep)) begin
                        if (s < 8'd2) bad = 1'b1;
                        if (s > longest) longest = s;
                        if (6'((9'(s) + 9'd7) >> 3) > mb) mb = 6'((9'(s) + 9'd7) >> 3);
                    end
                end
                most_blocks <= mb;
                if (mid < 32'(longest) || 33'(mid) + 33'(longest) > 33'h0_FFFF_FFFF) bad = 1'b1;
                still <= nx == 16'd0 || ny == 16'd0;
                if (nx != 16'd0 && ny != 16'd0) begin
                    if (p == 5'd31 || 32'(nx) > (32'd1 << NXB) || 32'(ny) > (32'd1 << NYB)
                        || x0 >= 32'sh0100_0000 || x0 <= -32'sh0100_0000
                        || y0 >= 32'sh0100_0000 || y0 <= -32'sh0100_0000)
                        bad = 1'b1;
                end
                ps <= (p == 5'd31) ? 4'd4 : p[3:0];
                q_lo <= -(36'sd1 <<< ((p == 5'd31) ? 4'd4 : p[3:0]));
                q_hix <= $signed({20'b0, nx}) <<< ((p == 5'd31) ? 4'd4 : p[3:0]);
                q_hiy <= $signed({20'b0, ny}) <<< ((p == 5'd31) ? 4'd4 : p[3:0]);
                {cnx, cny, cx0, cy0, cmid} <= {nx, ny, x0, y0, mid};
                error <= bad;
                tb_at <= '0;
                if (bad) begin
                    done <= 1'b1;
                end else begin
                    phase <= TABLES;
                end
            end
            TABLES: begin
                // One entry of each table per clock; the last written
                // three clocks after it started.
                tb_at <= tb_at + 1'b1;
                if (32'(tb_at) == TN + 3) phase <= EVENTS;
            end
            EVENTS: if (ev_end) begin
                // The last events are in e1 and e2: the first rate block
                // goes out three clocks from now at the soonest, after them.
                phase <= RSCAN;
                pix <= '0;
                px_x <= '0;
                px_y <= '0;
                rs_v <= 1'b0;
                rm_v <= 1'b0;
                rq_v <= 1'b0;
            end
            RSCAN: begin
                // A read's state arrives the clock after it is issued
                // (rs_*), is registered the next (rm_*, rate_r) and its
                // rate the next (rq_*, rate_now_r): a pixel with a static
                // rate sends its blocks (ROPS), the two reads behind it
                // are dropped, and the reads go on after it.
                rm_v <= rs_v;
                {rm_pix, rm_x, rm_y} <= {rs_pix, rs_x, rs_y};
                rq_v <= rm_v;
                {rq_pix, rq_x, rq_y} <= {rm_pix, rm_x, rm_y};
                rs_v <= 1'b0;
                if (rq_v && rate_now_r != 16'd0 && most_blocks != 6'd0) begin
                    r16 <= rate_now_r;
                    cur_x <= rq_x;
                    cur_y <= rq_y;
                    blk <= '0;
                    rm_v <= 1'b0;
                    rq_v <= 1'b0;
                    phase <= RPREP;
                    pix <= rq_pix + 32'd1;
                    if (rq_x == 16'(W - 1)) begin
                        px_x <= '0;
                        px_y <= rq_y + 1'b1;
                    end else begin
                        px_x <= rq_x + 1'b1;
                        px_y <= rq_y;
                    end
                end else if (pix != 32'(PX)) begin
                    rate_addr <= AW'(pix);
                    rs_v <= 1'b1;
                    rs_pix <= pix;
                    rs_x <= px_x;
                    rs_y <= px_y;
                    pix <= pix + 32'd1;
                    if (px_x == 16'(W - 1)) begin
                        px_x <= '0;
                        px_y <= px_y + 1'b1;
                    end else begin
                        px_x <= px_x + 1'b1;
                    end
                end else if (!rs_v && !rm_v && !rq_v) begin
                    phase <= DRAIN;
                    drain <= '0;
                end
            end
            RPREP: begin
                sub8 <= 16'((32'(r16) * 32'd512 + 32'd32768) >> 16);
                for (int k = 0; k < NR; k++)
                    sub_last[k] <= 16'((32'(r16) * 32'(n_last[k]) * 32'd64 + 32'd32768) >> 16);
                phase <= ROPS;
            end
            ROPS: begin
                if (blk == most_blocks - 6'd1) phase <= RSCAN;
                blk <= blk + 1'b1;
            end
            DRAIN: begin
                drain <= drain + 1'b1;
                if (drain == 5'(DEPTH)) begin
                    phase <= OUT;
                    o_run <= 1'b1;
                    o_pix <= '0;
                end
            end
            OUT: begin
                if (o_pix == AW'(PX - 1)) begin
                    o_run <= 1'b0;
                    phase <= IDLE;
                    done <= 1'b1;
                end else begin
                    o_pix <= o_pix + 1'b1;
                end
            end
            default: phase <= IDLE;
        endcase
    end
endmodule
