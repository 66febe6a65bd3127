// spiv's event ring: the light model's events of the last ticks, kept
// for the rung frames (spiv_rungs.sv), and its reader. Bit-exact with
// spiv-core's `rungs::EventRing` (through the C ABI's `spiv_ring_push`
// and `spiv_ring_events`; fpga/tb/tb_ring.cpp checks every event read
// and where the ring stands after every plane).
//
// Writer: a plane opens its tick t (in_open; t must be the ring's next
// tick, else `bad_tick` and the plane is ignored), its events follow one
// per clock while in_ready (pixel, the tick it belongs to, sign), and
// in_close ends it. Opening drops the oldest tick when the ring holds
// DEPTH ticks; an event that does not fit drops the oldest ticks until it
// does (one clock to drop a tick and one to read where the next begins),
// counted in `evicted`, and is itself dropped and counted in `lost` when
// its own tick fills the ring. Each entry is the pixel << 6, the ticks it
// was settled late (at most 31) << 1, and the sign: the core's layout.
//
// Reader (between planes): rd_start with ticks a..b streams the events of
// those ticks the ring holds, one per clock, in the order they were
// stored (the ticks from max(a, first) to b + 16 — events settled up to
// 16 ticks late — each tick's events kept when their own tick is in
// a..b), then rd_done.
//
// Capacities are powers of two: CAP = 2^CAPB events, DEPTH = 2^DEPB - 1
// ticks (`starts` holds DEPTH + 1 entries; the core takes any size, and
// the testbench sizes the core's ring the same). The starts are kept twice
// (one copy for the writer, one for the reader); the entries in one
// simple dual-port RAM.

module spiv_ring #(
    parameter integer CAPB = 16,  // log2 of the events held (2..=26)
    parameter integer DEPB = 9    // log2 of DEPTH + 1 (1..=16)
) (
    input  logic        clk,
    input  logic        rst,
    input  logic [31:0] first_tick,  // the tick the first plane gets (taken in reset)
    // writer
    input  logic        in_open,
    input  logic [31:0] in_tick,
    input  logic        in_valid,
    output logic        in_ready,
    input  logic [25:0] in_index,
    input  logic [31:0] in_etick,    // the event's own tick (<= the plane's)
    input  logic        in_neg,
    input  logic        in_close,
    // reader
    input  logic        rd_start,
    input  logic [31:0] rd_a,
    input  logic [31:0] rd_b,
    output logic        ev_valid,
    output logic [25:0] ev_index,
    output logic [31:0] ev_tick,
    output logic        ev_neg,
    output logic        rd_done,
    // where it stands
    output logic [31:0] first,
    output logic [31:0] next,
    output logic [31:0] stored,
    output logic [31:0] lost,
    output logic [31:0] evicted,
    output logic        bad_tick
);
    localparam integer CAP = 1 << CAPB;
    localparam integer SLOTS = 1 << DEPB;
    localparam logic [31:0] DEPTH = 32'(SLOTS - 1);
    localparam logic [31:0] TOLERANCE = 32'd16;

    initial begin
        if (CAPB < 2 || CAPB > 26 || DEPB < 1 || DEPB > 16)
            $error("spiv_ring: CAPB must be 2..=26 and DEPB 1..=16");
    end

    logic [31:0] entries [CAP];
    logic [31:0] starts_w [SLOTS];  // the writer's copy
    logic [31:0] starts_r [SLOTS];  // the reader's copy

    // ---- writer ----------------------------------------------------------
    typedef enum logic [1:0] {W_IDLE, W_OPEN, W_READY, W_FETCH} wstate_t;
    wstate_t     ws;
    logic [31:0] t;           // the open plane's tick
    logic [31:0] oldest;      // starts[slot(first)]
    logic        held;        // an event waits for room
    logic [31:0] held_entry;
    logic        fetch_wait;  // the read of starts[slot(first)] is on its way
    logic [31:0] starts_q;

    // the event as an entry
    logic [31:0] late, entry;
    always_comb begin
        late = t - in_etick;
        if (late > 31) late = 31;
        entry = {in_index, late[4:0], in_neg};
    end
    logic [31:0] cand;        // the entry being placed
    logic        fits;
    always_comb begin
        cand = held ? held_entry : entry;
        fits = (stored - oldest) < 32'(CAP);
    end
    assign in_ready = ws == W_READY && !held;

    always_ff @(posedge clk) begin
        starts_q <= starts_w[DEPB'(first)];
    end

    always_ff @(posedge clk) begin
        if (rst) begin
            ws <= W_IDLE;
            first <= first_tick;
            next <= first_tick;
            stored <= 0;
            lost <= 0;
            evicted <= 0;
            held <= 0;
            fetch_wait <= 0;
            bad_tick <= 0;
            oldest <= 0;
        end else begin
            case (ws)
                W_IDLE: if (in_open) begin
                    if (in_tick != next) begin
                        bad_tick <= 1;
                    end else begin
                        t <= in_tick;
                        // drop the oldest tick when DEPTH are held
                        if (next - first >= DEPTH) first <= first + 1;
                        starts_w[DEPB'(in_tick)] <= stored;
                        starts_r[DEPB'(in_tick)] <= stored;
                        ws <= W_OPEN;
                    end
                end
                W_OPEN: begin
                    // where the oldest tick held begins, read again
                    fetch_wait <= 1;
                    ws <= W_FETCH;
                end
                W_FETCH: begin
                    // one clock for the address, one for the data
                    if (fetch_wait) begin
                        fetch_wait <= 0;
                    end else begin
                        oldest <= starts_q;
                        ws <= W_READY;
                    end
                end
                W_READY: begin
                    if (held || in_valid) begin
                        if (fits) begin
                            entries[CAPB'(stored)] <= cand;
                            stored <= stored + 1;
                            held <= 0;
                        end else if (first == t) begin
                            if (lost != 32'hffffffff) lost <= lost + 1;
                            held <= 0;
                        end else begin
                            held <= 1;
                            held_entry <= cand;
                            first <= first + 1;
                            evicted <= evicted + 1;
                            ws <= W_OPEN;
                        end
                    end else if (in_close) begin
                        next <= t + 1;
                        ws <= W_IDLE;
                    end
                end
                default: ws <= W_IDLE;
            endcase
        end
    end

    // ---- reader ----------------------------------------------------------
    typedef enum logic [2:0] {R_IDLE, R_S0, R_S0W, R_S1, R_S1W, R_ENT, R_DONE} rstate_t;
    rstate_t     rs;
    logic [31:0] ra, rb, rt, rhi, s0, s1, k;
    logic [31:0] rstarts_q, entry_q;
    logic [DEPB-1:0] raddr;
    logic        pend;        // an entry read is on its way
    logic [31:0] pend_t;
    // the entry read, registered once more before it is judged (the block
    // RAMs' output multiplexer is a clock of its own)
    logic        pend2;
    logic [31:0] pend_t2, entry_q2;
    always_ff @(posedge clk) begin
        rstarts_q <= starts_r[raddr];
        entry_q <= entries[CAPB'(k)];
        entry_q2 <= entry_q;
        pend_t2 <= pend_t;
        pend2 <= !rst && pend;
    end
    always_comb begin
        raddr = (rs == R_S0) ? DEPB'(rt) : DEPB'(rt + 1);
    end

    // the last tick read: b + 16, saturating
    logic [31:0] bt;
    always_comb bt = (rd_b > 32'hffffffff - TOLERANCE) ? 32'hffffffff : rd_b + TOLERANCE;

    // the entry read two clocks ago, as an event
    logic [31:0] e_tick;
    always_comb e_tick = pend_t2 - {27'b0, entry_q2[5:1]};

    always_ff @(posedge clk) begin
        ev_valid <= 0;
        rd_done <= 0;
        if (rst) begin
            rs <= R_IDLE;
            pend <= 0;
        end else begin
            // the entry read two clocks ago
            if (pend2 && e_tick >= ra && e_tick < rb) begin
                ev_valid <= 1;
                ev_index <= entry_q2[31:6];
                ev_tick <= e_tick;
                ev_neg <= entry_q2[0];
            end
            pend <= 0;
            case (rs)
                R_IDLE: if (rd_start) begin
                    ra <= rd_a;
                    rb <= rd_b;
                    rt <= (rd_a > first) ? rd_a : first;
                    rhi <= (bt < next) ? bt : next;
                    rs <= R_S0;
                end
                R_S0: rs <= (rt < rhi) ? R_S0W : R_DONE;
                R_S0W: begin
                    s0 <= rstarts_q;
                    rs <= R_S1;
                end
                R_S1: begin
                    if (rt + 1 == next) begin
                        s1 <= stored;
                        k <= s0;
                        rs <= R_ENT;
                    end else begin
                        rs <= R_S1W;
                    end
                end
                R_S1W: begin
                    s1 <= rstarts_q;
                    k <= s0;
                    rs <= R_ENT;
                end
                R_ENT: begin
                    if (k != s1) begin
                        pend <= 1;
                        pend_t <= rt;
                        k <= k + 1;
                    end else begin
                        // the next tick begins where this one ended
                        rt <= rt + 1;
                        s0 <= s1;
                        rs <= (rt + 1 < rhi) ? R_S1 : R_DONE;
                    end
                end
                R_DONE: begin
                    if (!pend && !pend2) begin
                        rd_done <= 1;
                        rs <= R_IDLE;
                    end
                end
                default: rs <= R_IDLE;
            endcase
        end
    end
endmodule
