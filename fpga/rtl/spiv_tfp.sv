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
// Latency 3 clocks from in_bits to out_gray. in_valid may pause; planes
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
        if (BEATS < 2 || W * H % P != 0 || NMAX < 3 || NMAX > 255 || FS < 1 || FS > 255)
            $fatal(1, "spiv_tfp: W*H must be at least two beats of P pixels; NMAX 3..255; FS 1..255");
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
    // The schedule: the next frame's centre tick, and which member.
    logic [31:0]      next_k, pair_k;
    logic             member_b;
    logic             due;        // this plane ends the next frame's window
    logic [8:0]       len;        // the window as clipped, ticks
    logic [SHIFT:0]   r;          // R(len)

    wire [7:0]  half_up = (window + 8'd1) >> 1;             // ceil(window / 2)
    wire [31:0] due_tick = next_k + {24'd0, half_up} - 32'd1;
    wire        plane_start = in_valid && beat == '0;
    wire        now_due = (tick == due_tick);
    wire        passed = (tick > due_tick);
    wire [31:0] held = tick + 32'd1;
    wire [8:0]  now_len = (held < {24'd0, window}) ? held[8:0] : {1'b0, window};

    always_ff @(posedge clk) begin
        if (rst) begin
            beat <= '0;
            tick <= '0;
            next_k <= first;
            pair_k <= first;
            member_b <= 1'b0;
            due <= 1'b0;
            len <= 9'd1;
            r <= '0;
            missed <= '0;
        end else if (in_valid) begin
            if (beat == '0) begin
                due <= now_due;
                len <= now_len;
                r <= recip[now_len[7:0]];
                if (passed) missed <= missed + 32'd1;
                if (now_due || passed) begin
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
            if (beat == ABITS'(BEATS - 1)) begin
                beat <= '0;
                tick <= tick + 32'd1;
            end else begin
                beat <= beat + 1'b1;
            end
        end
    end

    // ---- stage 1: read the history word, count -------------------------
    logic             s1_valid, s1_start, s1_due;
    logic [ABITS-1:0] s1_beat;
    logic [P-1:0]     s1_bits;
    logic [SLOTS*P-1:0] s1_hist;
    logic [31:0]      s1_k;
    logic [8:0]       s1_len;
    logic [SHIFT:0]   s1_r;

    always_ff @(posedge clk) begin
        s1_valid <= in_valid && !rst;
        // The window of the beat's plane travels with the beat.
        s1_len <= plane_start ? now_len : len;
        s1_r <= plane_start ? recip[now_len[7:0]] : r;
        s1_beat <= beat;
        s1_bits <= in_bits;
        s1_hist <= hist[beat];
        s1_start <= plane_start;
        s1_due <= plane_start ? now_due : due;
        if (plane_start) s1_k <= next_k;
    end

    // Write back: the newest plane into slot 0, the others one slot older.
    always_ff @(posedge clk) begin
        if (s1_valid) hist[s1_beat] <= {s1_hist[(SLOTS-1)*P-1:0], s1_bits};
    end

    // ---- stages 2 and 3, per lane ----------------------------------------
    logic             s2_valid, s2_start;
    logic [31:0]      s2_k;
    logic [SHIFT:0]   s2_r;
    always_ff @(posedge clk) begin
        s2_valid <= s1_valid && s1_due;
        s2_start <= s1_start;
        s2_k <= s1_k;
        s2_r <= s1_r;
        out_valid <= s2_valid;
        out_start <= s2_valid && s2_start;
        out_tick <= s2_k;
    end

    genvar g;
    generate
        for (g = 0; g < P; g = g + 1) begin : lane
            // The current bit and the bits of the last window - 1 planes.
            logic [8:0] count;
            always_comb begin
                count = {8'd0, s1_bits[g]};
                for (int j = 0; j < SLOTS; j = j + 1)
                    if (j + 1 < int'(window))
                        count = count + {8'd0, s1_hist[j*P + g]};
            end
            // Stage 2: x = FS * c + len / 2; stage 3: gray = x * R >> SHIFT.
            logic [16:0] x;
            always_ff @(posedge clk) begin
                x <= 17'(FS) * {8'd0, count} + {9'd0, s1_len[8:1]};
                out_gray[8*g +: 8] <= 8'((({27'd0, x} * {17'd0, s2_r}) >> SHIFT));
            end
        end
    endgenerate

    assign planes = tick;
endmodule
