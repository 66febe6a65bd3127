// spiv's lossless `Rice` tile coder at one sample per clock: a band of
// rows of a frame in, the payload's bytes out, bit-exact with spiv-core's
// `wire::codec` (`encode_tile` with `Encoding::Rice`, through the C ABI's
// `spiv_encode_tile`; fpga/tb/tb_rice.cpp checks every byte).
//
// Per sample: the LOCO-I median edge predictor from the left, upper and
// upper-left samples (the first row from the left, a row's first sample
// from above, the tile's first from 0), the zigzag of the residual, and
// its Rice code with the adaptive parameter k, the smallest k <= 16 with
// N * 2^k >= A (A the running sum of the coded values from 4, N their
// count from 1, both halved when N reaches 64). A quotient z >> k of 24 or
// more is sent as 24 ones and z in 18 bits. Bits go out MSB first in
// 32-bit big-endian words; the last word's bytes are padded with zeros.
//
// The row above lives in a line buffer of WMAX samples (one read and one
// write per clock). A tile's samples are streamed row by row, `width` per
// row, in_first on its first sample and in_last on its last; in_valid may
// pause. Out come up to two words per clock (a sample's code is at most
// 42 bits), then at the end the tail of 0..4 bytes and the tile's summary:
// its payload bytes and whether any level exceeds 255 (`wide`). The core
// sends the tile as Rice when the payload is shorter than the raw tile
// (one byte per sample, two when wide), else raw (`rice` low): the raw
// bytes are the frame's samples, which the sender reads again.
//
// Latency: 5 clocks from a sample to its code's words.

module spiv_rice #(
    parameter integer WMAX = 1024  // widest row, samples (2..=65535)
) (
    input  logic        clk,
    input  logic        rst,
    input  logic [15:0] width,      // samples per row, 1..=WMAX, held per tile
    input  logic        in_valid,
    input  logic        in_first,   // the tile's first sample
    input  logic        in_last,    // the tile's last sample
    input  logic [15:0] in_sample,
    // payload words, MSB first; out_words of them (0..2) in out_data, the
    // first in bits 63:32
    output logic [1:0]  out_words,
    output logic [63:0] out_data,
    // the tile's end: out_tail_bytes (0..4) bytes in out_tail (the first
    // in bits 31:24), its payload length in bytes, wide and the choice
    output logic        out_done,
    output logic [2:0]  out_tail_bytes,
    output logic [31:0] out_tail,
    output logic [31:0] out_bytes,
    output logic        out_wide,
    output logic        out_rice
);
    localparam integer AW = $clog2(WMAX);
    localparam integer ESCAPE = 24;
    localparam integer ESCAPE_BITS = 18;

    initial begin
        if (WMAX < 2 || WMAX > 65535)
            $error("spiv_rice: WMAX must be 2..=65535");
    end

    // ---- stage 0: position in the tile, the line buffer ------------------
    logic [15:0] col;        // column of the next sample
    logic        row0;       // the next sample is on the tile's first row
    logic [15:0] line [WMAX];
    logic [15:0] up_q;       // line[c] as read for the next sample
    logic [15:0] upleft;     // the sample above the previous one
    logic [15:0] left;       // the previous sample
    // The sample's own column and row (a tile's first starts afresh), the
    // column after it (0 after a row's last sample or a tile's last) and
    // the column read for the next sample.
    logic [15:0] c0, col_next, rd_col;
    logic        r0;
    always_comb begin
        c0 = in_first ? 16'd0 : col;
        r0 = in_first ? 1'b1 : row0;
        col_next = c0 + 16'd1;
        if (col_next >= width || in_last)
            col_next = 16'd0;
        rd_col = in_valid ? col_next : col;
    end

    // the line buffer: one read and one write per clock; a row of one
    // sample reads the sample just written
    logic [15:0] line_q;
    logic        fwd;
    always_ff @(posedge clk) begin
        line_q <= line[AW'(rd_col)];
        if (in_valid)
            line[AW'(c0)] <= in_sample;
    end
    logic [15:0] fwd_sample;
    always_ff @(posedge clk) begin
        fwd <= in_valid && rd_col == c0;
        fwd_sample <= in_sample;
    end
    always_comb up_q = fwd ? fwd_sample : line_q;

    // stage-1 registers: the sample and its neighbours
    logic        s1_v, s1_last, s1_first;
    logic [15:0] s1_x, s1_a, s1_b, s1_c;
    logic [1:0]  s1_kind;    // 0: tile's first, 1: first row, 2: row's first, 3: median
    always_ff @(posedge clk) begin
        if (rst) begin
            col <= 0;
            row0 <= 1;
            s1_v <= 0;
        end else begin
            s1_v <= in_valid;
            if (in_valid) begin
                s1_x <= in_sample;
                s1_a <= left;
                s1_b <= up_q;
                s1_c <= upleft;
                s1_first <= in_first;
                s1_last <= in_last;
                s1_kind <= (c0 == 0 && r0) ? 2'd0 : r0 ? 2'd1 : (c0 == 0) ? 2'd2 : 2'd3;
                left <= in_sample;
                upleft <= up_q;
                col <= col_next;
                row0 <= in_last ? 1'b1 : (r0 && col_next != 0);
            end
        end
    end

    // ---- stage 1: prediction and zigzag ---------------------------------
    logic signed [17:0] pa, pb, pc, lo, hi, g, pred, d;
    always_comb begin
        pa = {2'b0, s1_a};
        pb = {2'b0, s1_b};
        pc = {2'b0, s1_c};
        lo = (pa < pb) ? pa : pb;
        hi = (pa < pb) ? pb : pa;
        g = pa + pb - pc;
        case (s1_kind)
            2'd0: pred = 0;
            2'd1: pred = pa;
            2'd2: pred = pb;
            default: pred = (g < lo) ? lo : (g > hi) ? hi : g;
        endcase
        d = {2'b0, s1_x} - pred;
    end
    logic        s2_v, s2_last, s2_first, s2_wide;
    logic [17:0] s2_z;
    always_ff @(posedge clk) begin
        if (rst) begin
            s2_v <= 0;
        end else begin
            s2_v <= s1_v;
            if (s1_v) begin
                s2_z <= {d[16:0], 1'b0} ^ {18{d[17]}};
                s2_first <= s1_first;
                s2_last <= s1_last;
                s2_wide <= s1_x > 16'd255;
            end
        end
    end

    // ---- stage 2: the adaptive parameter --------------------------------
    // A and N after each sample, and k for the next one, computed as they
    // are updated (a tile's first sample takes k = 2, from A = 4, N = 1):
    // the recursion is one add, one halving and the compares per clock.
    logic [31:0] acc_a, a_now, a_next;
    logic [6:0]  acc_n, n_now, n_next;
    logic [4:0]  k_next, k_reg, k;
    always_comb begin
        a_now = s2_first ? 32'd4 : acc_a;
        n_now = s2_first ? 7'd1 : acc_n;
        k = s2_first ? 5'd2 : k_reg;
        a_next = a_now + {14'b0, s2_z};
        n_next = n_now + 7'd1;
        if (n_next >= 64) begin
            a_next = a_next >> 1;
            n_next = n_next >> 1;
        end
        // the smallest k <= 16 with N * 2^k >= A (16 if none)
        k_next = 16;
        for (int i = 16; i >= 0; --i)
            if (({25'b0, n_next} << i) >= a_next) k_next = 5'(i);
    end
    logic        s3_v, s3_last, s3_first, s3_wide;
    logic [17:0] s3_z;
    logic [4:0]  s3_k;
    always_ff @(posedge clk) begin
        if (rst) begin
            s3_v <= 0;
        end else begin
            s3_v <= s2_v;
            if (s2_v) begin
                acc_a <= a_next;
                acc_n <= n_next;
                k_reg <= k_next;
                s3_z <= s2_z;
                s3_k <= k;
                s3_first <= s2_first;
                s3_last <= s2_last;
                s3_wide <= s2_wide;
            end
        end
    end

    // ---- stage 3: the code -----------------------------------------------
    logic [17:0] q;
    logic [41:0] ones, low;
    always_comb begin
        q = s3_z >> s3_k;
        ones = (42'd1 << q[4:0]) - 42'd1;
        low = {24'b0, s3_z} & ((42'd1 << s3_k) - 42'd1);
    end
    logic        s4_v, s4_last, s4_first, s4_wide;
    logic [41:0] s4_code;
    logic [5:0]  s4_len;
    always_ff @(posedge clk) begin
        if (rst) begin
            s4_v <= 0;
        end else begin
            s4_v <= s3_v;
            if (s3_v) begin
                if (q < 18'(ESCAPE)) begin
                    // q ones, a zero, the k low bits of z
                    s4_code <= (ones << (s3_k + 5'd1)) | low;
                    s4_len <= 6'(q[4:0]) + 6'd1 + 6'(s3_k);
                end else begin
                    s4_code <= {24'hffffff, s3_z};
                    s4_len <= 6'(ESCAPE + ESCAPE_BITS);
                end
                s4_first <= s3_first;
                s4_last <= s3_last;
                s4_wide <= s3_wide;
            end
        end
    end

    // samples of the tile so far (the raw payload's length)
    logic [31:0] sample_count;
    logic [31:0] count_q;
    always_comb sample_count = (s4_first ? 32'd0 : count_q) + 32'd1;
    always_ff @(posedge clk) begin
        if (rst) count_q <= 0;
        else if (s4_v) count_q <= sample_count;
    end

    // ---- stage 4: the bit packer ----------------------------------------
    // `pend` low bits of `bits` are pending (below 32 between samples).
    logic [79:0] bits, b, top;
    logic [5:0]  pend;
    logic [6:0]  total, left_bits;
    logic [31:0] nbytes, sent, tail, all;
    logic [32:0] raw;
    logic [2:0]  tail_bytes;
    logic        wide, w;
    logic [1:0]  words;
    always_comb begin
        b = (bits << s4_len) | {38'b0, s4_code};
        total = (s4_first ? 7'd0 : {1'b0, pend}) + {1'b0, s4_len};
        top = b << (7'd80 - total);  // the pending bits at the top
        sent = s4_first ? 32'd0 : nbytes;
        w = (s4_first ? 1'b0 : wide) | s4_wide;
        if (total >= 64) begin
            words = 2;
            left_bits = total - 7'd64;
            sent = sent + 32'd8;
        end else if (total >= 32) begin
            words = 1;
            left_bits = total - 7'd32;
            sent = sent + 32'd4;
        end else begin
            words = 0;
            left_bits = total;
        end
        // the tail: the remaining bits, padded to whole bytes
        tail_bytes = 3'((left_bits + 7'd7) >> 3);
        tail = (left_bits == 0) ? 32'd0 : 32'(b << (7'd32 - left_bits));
        all = sent + 32'(tail_bytes);
        raw = w ? {sample_count, 1'b0} : {1'b0, sample_count};
    end
    always_ff @(posedge clk) begin
        out_words <= 0;
        out_done <= 0;
        if (rst) begin
            pend <= 0;
            nbytes <= 0;
            wide <= 0;
        end else if (s4_v) begin
            out_words <= words;
            out_data <= top[79:16];
            bits <= b;
            pend <= 6'(left_bits);
            wide <= w;
            nbytes <= sent;
            if (s4_last) begin
                out_done <= 1;
                out_tail_bytes <= tail_bytes;
                out_tail <= tail;
                out_bytes <= all;
                out_wide <= w;
                out_rice <= {1'b0, all} < raw;
            end
        end
    end
endmodule
