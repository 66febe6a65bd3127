// spiv's TFP frame at sensor rate: spike planes in, P pixels per clock;
// at every scheduled frame, the frame out in the same pass as the plane
// that ends its window. Bit-exact with spiv-core's `window::tfp` (through
// the C ABI's `spiv_make_frame`; fpga/tb/tb_tfp.cpp checks every frame).
//
//   gray = round(FS * c / len), c the pixel's spikes over the window of
//   `window` ticks centred on the frame's tick k, [k - window/2,
//   k - window/2 + window), len that window clipped to the ticks seen.
//
// Per pixel the design keeps its last NMAX - 1 spike bits, one word of
// (NMAX - 1) * P bits per P pixels, read, shifted and written back once
// per plane (a simple dual-port RAM, one read and one write per clock).
// The division is a multiply by a reciprocal from a ROM of 255 words,
// exact for every count and window (x * e < 2^SHIFT, docs/embedded.md).
//
// Schedule: frames at first + i * every and first + i * every + dt
// (centre ticks), as the sidecar's loop (spiv_core::sidecar::Schedule);
// a frame is due when the plane of tick k + ceil(window / 2) - 1 arrives.
// One frame per plane: a frame due on a plane that already ended another
// (every == dt) is skipped and counted (`missed`).
//
// Latency 7 clocks from in_bits to out_gray. in_valid may pause; planes
// are W * H / P beats back to back in stored pixel order (pixel y * W + x
// in lane x % P of beat (y * W + x) / P).

module spiv_tfp #(
    parameter integer W = 128,
    parameter integer H = 64,
    parameter integer P = 32,     // pixels per clock; W * H % P == 0
    parameter integer NMAX = 16,  // longest window, ticks (3..=255)
    parameter integer FS = 255    // full-scale gray level (1..=255)
) (
    input  logic                 clk,
    input  logic                 rst,
    // configuration, held while planes stream
    input  logic [7:0]           window,   // 1..=NMAX ticks
    input  logic [31:0]          first,    // centre tick of the first frame
    input  logic [31:0]          dt,       // ticks between a pair's frames
    input  logic [31:0]          every,    // ticks between pairs (>= dt)
    // spike planes in
    input  logic                 in_valid,
    input  logic [P-1:0]         in_bits,
    // frames out
    output logic                 out_valid,
    output logic                 out_start,  // first beat of a frame
    output logic [31:0]          out_tick,   // the frame's centre tick
    output logic [8*P-1:0]       out_gray,
    // ticks (planes) taken so far
    output logic [31:0]          planes,
    // scheduled frames whose last plane had passed (a frame due on the
    // plane of another: every == dt), skipped and counted
    output logic [31:0]          missed
);
    localparam integer BEATS = W * H / P;
    localparam integer ABITS = $clog2(BEATS);
    localparam integer SLOTS = NMAX - 1;
    localparam integer SHIFT = 26;

    initial begin
        if (BEATS < 3 || W * H % P != 0 || NMAX < 3 || NMAX > 255 || FS < 1 || FS > 255)
            $fatal(1, "spiv_tfp: W*H must be at least three beats of P pixels; NMAX 3..255; FS 1..255");
    end

    // ---- reciprocals: R(len) = ceil(2^SHIFT / len) --------------------
    logic [SHIFT:0] recip [0:255];
    initial begin
        recip[0] = 0;
        for (int i = 1; i < 256; i = i + 1)
            recip[i] = (SHIFT+1)'(((1 << SHIFT) + i - 1) / i);
    end

    // ---- per-pixel bit history ----------------------------------------
    logic [SLOTS*P-1:0] hist [0:BEATS-1];
    initial begin
        for (int i = 0; i < BEATS; i = i + 1) hist[i] = '0;
    end

    // ---- the plane and beat being taken -------------------------------
    logic [ABITS-1:0] beat;
    logic [31:0]      tick;
    // The schedule: the next frame's centre tick, its pair's first, and
    // whether it is the pair's second.
    logic [31:0]      next_k, pair_k;
    logic             member_b;
    // Of the plane being taken: it ends the next frame's window (`due`),
    // that window as clipped (`len`, ticks) and R(len).
    logic             due;
    logic [8:0]       len;
    logic [SHIFT:0]   r;
    // The same for the plane after it, worked out while this one streams
    // (two beats before its end), so no plane starts on a long path.
    logic             pre_due, pre_passed;
    logic [8:0]       pre_len;
    logic [SHIFT:0]   pre_r;

    wire [31:0] half_up = {24'd0, (window + 8'd1) >> 1};      // ceil(window / 2)
    wire [31:0] due_tick = next_k + half_up - 32'd1;
    wire [31:0] first_due = first + half_up - 32'd1;
    wire [31:0] next_tick = tick + 32'd1;
    wire [31:0] next_held = tick + 32'd2;                      // ticks seen by then
    wire        plane_start = in_valid && beat == '0;

    always_ff @(posedge clk) begin
        if (rst) begin
            beat <= '0;
            tick <= '0;
            next_k <= first;
            pair_k <= first;
            member_b <= 1'b0;
            due <= 1'b0;
            len <= 9'd1;
            r <= recip[1];
            pre_due <= first_due == 32'd0;
            pre_passed <= 1'b0;
            pre_len <= 9'd1;
            pre_r <= recip[1];
            missed <= '0;
        end else if (in_valid) begin
            if (beat == '0) begin
                due <= pre_due;
                len <= pre_len;
                r <= pre_r;
                if (pre_passed) missed <= missed + 32'd1;
                if (pre_due || pre_passed) begin
                    // The frame after this one.
                    if (member_b) begin
                        pair_k <= pair_k + every;
                        next_k <= pair_k + every;
                    end else begin
                        next_k <= pair_k + dt;
                    end
                    member_b <= ~member_b;
                end
            end
            if (beat == ABITS'(BEATS - 2)) begin
                pre_due <= next_tick == due_tick;
                pre_passed <= next_tick > due_tick;
                pre_len <= (next_held < {24'd0, window}) ? next_held[8:0] : {1'b0, window};
            end
            if (beat == ABITS'(BEATS - 1)) begin
                pre_r <= recip[pre_len[7:0]];
                beat <= '0;
                tick <= next_tick;
            end else begin
                beat <= beat + 1'b1;
            end
        end
    end

    // ---- stage 1: the history word read (block RAM) ---------------------
    logic             s1_valid, s1_start, s1_due;
    logic [ABITS-1:0] s1_beat;
    logic [P-1:0]     s1_bits;
    logic [SLOTS*P-1:0] s1_hist;
    logic [31:0]      s1_k;
    logic [8:0]       s1_len;
    logic [SHIFT:0]   s1_r;

    always_ff @(posedge clk) begin
        s1_valid <= in_valid && !rst;
        s1_beat <= beat;
        s1_bits <= in_bits;
        s1_hist <= hist[beat];
        s1_start <= plane_start;
        // The window of the beat's plane travels with the beat.
        s1_due <= plane_start ? pre_due : due;
        s1_len <= plane_start ? pre_len : len;
        s1_r <= plane_start ? pre_r : r;
        if (plane_start) s1_k <= next_k;
    end

    // ---- stage 2: the word registered; written back one plane older -----
    logic             s2_valid, s2_start, s2_due;
    logic [ABITS-1:0] s2_beat;
    logic [P-1:0]     s2_bits;
    logic [SLOTS*P-1:0] s2_hist;
    logic [31:0]      s2_k;
    logic [8:0]       s2_len;
    logic [SHIFT:0]   s2_r;
    always_ff @(posedge clk) begin
        s2_valid <= s1_valid;
        s2_start <= s1_start;
        s2_due <= s1_due;
        s2_beat <= s1_beat;
        s2_bits <= s1_bits;
        s2_hist <= s1_hist;
        s2_k <= s1_k;
        s2_len <= s1_len;
        s2_r <= s1_r;
        // The newest plane into slot 0, the others one slot older.
        if (s2_valid) hist[s2_beat] <= {s2_hist[(SLOTS-1)*P-1:0], s2_bits};
    end

    // ---- stages 3 to 7: count in groups of four, their sum, FS * c +
    // len / 2, times R, shifted --------------------------------------------
    localparam integer BITS = SLOTS + 1;                 // a window's bits
    localparam integer GROUPS = (BITS + 3) / 4;
    logic [7:3]       v, st;
    logic [31:0]      k3, k4, k5, k6;
    logic [8:0]       len3, len4;
    logic [SHIFT:0]   r3, r4, r5;
    always_ff @(posedge clk) begin
        v[3] <= s2_valid && s2_due;
        st[3] <= s2_start;
        k3 <= s2_k;
        len3 <= s2_len;
        r3 <= s2_r;
        v[4] <= v[3];
        st[4] <= st[3];
        k4 <= k3;
        len4 <= len3;
        r4 <= r3;
        v[5] <= v[4];
        st[5] <= st[4];
        k5 <= k4;
        r5 <= r4;
        v[6] <= v[5];
        st[6] <= st[5];
        k6 <= k5;
        out_valid <= v[6];
        out_start <= v[6] && st[6];
        out_tick <= k6;
    end

    genvar g;
    generate
        for (g = 0; g < P; g = g + 1) begin : lane
            // The window's bits of this pixel: the current plane's, then
            // the last window - 1 planes' (bit j from j planes ago).
            logic [4*GROUPS-1:0] bits;
            always_comb begin
                bits = '0;
                bits[0] = s2_bits[g];
                for (int j = 0; j < SLOTS; j = j + 1)
                    bits[j + 1] = s2_hist[j*P + g] && (j + 1 < int'(window));
            end
            // Stage 3: each group of four bits counted; stage 4: the sum.
            logic [2:0] part [0:GROUPS-1];
            logic [8:0] count;
            always_ff @(posedge clk) begin
                for (int q = 0; q < GROUPS; q = q + 1)
                    part[q] <= 3'(bits[4*q]) + 3'(bits[4*q+1]) + 3'(bits[4*q+2]) + 3'(bits[4*q+3]);
            end
            always_ff @(posedge clk) begin
                logic [8:0] acc;
                acc = '0;
                for (int q = 0; q < GROUPS; q = q + 1) acc = acc + 9'(part[q]);
                count <= acc;
            end
            // Stage 5: x = FS * c + len / 2; 6: times R; 7: shifted.
            logic [16:0] x;
            logic [SHIFT+17:0] prod;
            always_ff @(posedge clk) begin
                x <= 17'(FS) * {8'd0, count} + {9'd0, len4[8:1]};
                prod <= {{(SHIFT+1){1'b0}}, x} * {17'd0, r5};
                out_gray[8*g +: 8] <= prod[SHIFT +: 8];
            end
        end
    endgenerate

    assign planes = tick;
endmodule
