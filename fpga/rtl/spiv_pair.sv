// The live mode's pair maker: the event ring (spiv_ring.sv) chained to
// the rung frames (spiv_rungs.sv). The light model's events go into the
// ring plane by plane; a pair starts the rung frames (their tables) and,
// once they take events, the ring's reader streams the events of ticks
// `ev_from` to the ring's next tick into them, in the order stored, then
// ends them. Bit-exact with spiv-core's `rungs::rung_frames` on the core's
// `EventRing` (fpga/tb/tb_live.cpp drives it inside spiv_live.sv).
//
// The ring's and the rung frames' ports are theirs (see those modules);
// `ev_from` is held with `start`. A pair whose ticks the ring no longer
// (or not yet) holds is refused, as the core refuses it.

module spiv_pair #(
    parameter integer W = 128,
    parameter integer H = 64,
    parameter integer NR = 8,
    parameter integer NXB = 6,
    parameter integer NYB = 6,
    parameter integer CAPB = 16,
    parameter integer DEPB = 9
) (
    input  logic                 clk,
    input  logic                 rst,
    input  logic [31:0]          first_tick,
    // the ring's writer
    input  logic                 in_open,
    input  logic [31:0]          in_tick,
    input  logic                 in_valid,
    output logic                 in_ready,
    input  logic [25:0]          in_index,
    input  logic [31:0]          in_etick,
    input  logic                 in_neg,
    input  logic                 in_close,
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
    // the light model's rates
    output logic [$clog2(W*H)-1:0] rate_addr,
    input  logic [31:0]          rate_q24,
    input  logic [7:0]           rate_flags,
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
    logic        ev_ready, ev_valid, ev_neg, rd_done, rd_start;
    logic [25:0] ev_index;
    logic [31:0] ev_tick, from_q;
    logic        pending;

    spiv_ring #(.CAPB(CAPB), .DEPB(DEPB)) ring (
        .clk, .rst, .first_tick,
        .in_open, .in_tick, .in_valid, .in_ready, .in_index, .in_etick, .in_neg, .in_close,
        .rd_start, .rd_a(from_q), .rd_b(ring_next),
        .ev_valid, .ev_index, .ev_tick, .ev_neg, .rd_done,
        .first(ring_first), .next(ring_next), .stored(ring_stored), .lost(ring_lost),
        .evicted(ring_evicted), .bad_tick(ring_bad_tick)
    );

    // A pair whose ticks the ring does not hold (mid - longest before its
    // first tick, mid + longest + 16 past its next) is refused, as the
    // core refuses it: done and error, no frames.
    logic [7:0]  longest;
    logic        unheld, refuse_q, rungs_done, rungs_error;
    logic [32:0] span_end;
    always_comb begin
        longest = 0;
        for (int k = 0; k < NR; ++k)
            if (k < int'(nsep) && seps[8*k +: 8] > longest) longest = seps[8*k +: 8];
        span_end = {1'b0, mid} + 33'(longest) + 33'd16;
        unheld = longest != 0 && ({24'b0, longest} > mid || mid - {24'b0, longest} < ring_first
                 || span_end > {1'b0, ring_next});
    end
    always_ff @(posedge clk) refuse_q <= !rst && start && unheld;
    assign done = rungs_done | refuse_q;
    assign error = rungs_error | refuse_q;

    spiv_rungs #(.W(W), .H(H), .NR(NR), .NXB(NXB), .NYB(NYB)) rungs (
        .clk, .rst,
        .node_we, .node_r, .node_c, .node_vx, .node_vy, .node_ax, .node_ay,
        .start(start && !unheld), .mid, .nsep, .seps, .nx, .ny, .x0, .y0, .pitch,
        .ev_ready, .ev_valid, .ev_index({6'b0, ev_index}), .ev_tick, .ev_neg, .ev_end(rd_done),
        .rate_addr, .rate_q24, .rate_flags,
        .out_valid, .out_index, .out_a, .out_b, .busy, .done(rungs_done), .error(rungs_error)
    );

    // The reader starts once the rung frames take events (their tables
    // made); a refused pair ends without it.
    always_comb rd_start = pending && ev_ready;
    always_ff @(posedge clk) begin
        if (rst) begin
            pending <= 0;
        end else if (start && !unheld) begin
            pending <= 1;
            from_q <= ev_from;
        end else if (rd_start || done) begin
            pending <= 0;
        end
    end
endmodule
