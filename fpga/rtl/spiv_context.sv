// spiv's lossless `Context` tile coder, the live mode's coding, one coded
// decision per clock: a band of rows of a frame in, the payload's bytes
// out, bit-exact with spiv-core's `wire::codec` (`encode_tile` with
// `Encoding::Context`, through the C ABI's `spiv_encode_tile`;
// fpga/tb/tb_context.cpp checks every byte).
//
// Per sample (`wire::codec::context`): the LOCO-I median edge predictor
// from the left, upper and upper-left samples and a context of 36 from
// the four causal neighbours (left, upper-left, above, upper-right): how
// much they vary (12 classes of |d - b| + |b - c| + |c - a|) and how
// bright the brightest is (3 classes); outside the tile the left
// neighbour stands for the missing row above and the one above for the
// missing left column. The residual is coded by the context's models
// (`wire::codec::range`): a zero flag; then its sign, and |v| - 1 as a
// zero flag, its bit length n in unary (models len[1..17]), its top bit
// below the leading one (model top[n - 1]) and its n - 2 lower bits at
// probability 1/2. Each coded bit is one step of LZMA's binary range
// coder (32-bit range, 12-bit probabilities moved 1/16 of the way, a
// cached byte and a count of 0xFF bytes a carry may still change) and
// its renormalisation, at most two bytes' shift per step. The tile ends
// with five shifts of the low word.
//
// The models' recursion is a serial chain per coded bit, so the coder
// takes one clock per bit: one for a sample whose residual is 0 (a flat
// or suppressed background), 3 when it is +-1, and 2 + 2n otherwise (n
// the bit length of |v| - 1). A sample taken is registered with its
// neighbours, then with its residual and context, and waits there while
// the one before it is coded; in_ready holds the stream while both
// registers are full. The 36 x 37 models are 12-bit
// words in a RAM; the next bit's model is known a clock ahead (the bits
// of a sample follow from its residual), so it is read then, or taken
// from the bit being coded when that updates the same model. A valid bit
// per model, cleared at a tile's first sample, stands for the tile's
// fresh models (probability 1/2).
//
// The row above lives in a line buffer of WMAX samples: sample x reads
// the one above x + 1 (its upper-right) before this row overwrites it;
// the ones above x and x - 1 were read for the samples before.
//
// Out: up to two byte runs per clock, each a head byte and then `count`
// bytes of `fill` (the range coder's pending 0xFF bytes, 0x00 after a
// carry); at the tile's end its payload bytes, whether any level exceeds
// 255 (`wide`) and the choice: Context when the payload is shorter than
// the raw tile (one byte per sample, two when wide), else raw, which the
// sender reads from the frame again.

module spiv_context #(
    parameter integer WMAX = 1024  // widest row, samples (2..=65535)
) (
    input  logic        clk,
    input  logic        rst,
    input  logic [15:0] width,      // samples per row, 1..=WMAX, held per tile
    input  logic        in_valid,
    output logic        in_ready,
    input  logic        in_first,   // the tile's first sample
    input  logic        in_last,    // the tile's last sample
    input  logic [15:0] in_sample,
    // byte runs: slot k (0 first) valid in out_valid[k], its head byte in
    // out_head[15 - 8k -: 8], its fill in out_fill[15 - 8k -: 8] and its
    // count in out_count[63 - 32k -: 32]
    output logic [1:0]  out_valid,
    output logic [15:0] out_head,
    output logic [15:0] out_fill,
    output logic [63:0] out_count,
    output logic        out_done,
    output logic [31:0] out_bytes,
    output logic        out_wide,
    output logic        out_context
);
    localparam integer AW = $clog2(WMAX);
    localparam integer MODELS = 37;             // per context
    localparam integer CONTEXTS = 36;
    localparam integer NM = MODELS * CONTEXTS;  // 1,332
    localparam integer MAG_BITS = 18;

    initial begin
        if (WMAX < 2 || WMAX > 65535)
            $error("spiv_context: WMAX must be 2..=65535");
    end

    // ---- the sample in: neighbours, prediction, context -------------------
    logic [15:0] col;       // column of the next sample
    logic        row0;      // the next sample is on the tile's first row
    logic [15:0] left;      // the previous sample of this row
    logic [15:0] up_x;      // the sample above the next one
    logic [15:0] up_l;      // the sample above and left of the next one
    logic [15:0] line [WMAX];
    logic        take;
    logic [15:0] c0, c1;
    logic        r0;
    logic [15:0] up_r, na, nb, nc, nd;
    always_comb begin
        c0 = in_first ? 16'd0 : col;
        r0 = in_first ? 1'b1 : row0;
        c1 = c0 + 16'd1;
        up_r = line[AW'(c1)];
        if (r0) begin
            na = (c0 == 0) ? 16'd0 : left;
            nb = na;
            nc = na;
            nd = na;
        end else begin
            nb = up_x;
            na = (c0 == 0) ? up_x : left;
            nc = (c0 == 0) ? up_x : up_l;
            nd = (c1 < width) ? up_r : up_x;
        end
    end

    // The sample and its neighbours, registered (n_*); they go on to the
    // waiting register when it is free or frees.
    logic        n_valid, n_first, n_last, go;
    logic [15:0] n_x, n_a, n_b, n_c, n_d;

    // activity, brightness and their classes; the median predictor
    logic [17:0] act;
    logic [15:0] bright;
    logic [3:0]  act_class;
    logic [1:0]  bright_class;
    logic signed [17:0] sa, sb, sc, lo, hi, g, pred, res;
    logic [10:0] act_base, base;
    logic [15:0] db, bc, ca;
    always_comb begin
        db = (n_d > n_b) ? n_d - n_b : n_b - n_d;
        bc = (n_b > n_c) ? n_b - n_c : n_c - n_b;
        ca = (n_c > n_a) ? n_c - n_a : n_a - n_c;
        act = 18'(db) + 18'(bc) + 18'(ca);
        bright = n_a;
        if (n_b > bright) bright = n_b;
        if (n_c > bright) bright = n_c;
        if (n_d > bright) bright = n_d;
        // the activity classes' upper bounds (`context::ACTIVITY`)
        act_class = 4'(act > 18'd0) + 4'(act > 18'd1) + 4'(act > 18'd2) + 4'(act > 18'd4)
                  + 4'(act > 18'd6) + 4'(act > 18'd9) + 4'(act > 18'd14) + 4'(act > 18'd21)
                  + 4'(act > 18'd32) + 4'(act > 18'd48) + 4'(act > 18'd72);
        bright_class = 0;
        if (bright > 16'd3) bright_class = bright_class + 2'd1;
        if (bright > 16'd24) bright_class = bright_class + 2'd1;
        sa = {2'b0, n_a};
        sb = {2'b0, n_b};
        sc = {2'b0, n_c};
        lo = (sa < sb) ? sa : sb;
        hi = (sa < sb) ? sb : sa;
        g = sa + sb - sc;
        pred = (g < lo) ? lo : (g > hi) ? hi : g;
        res = {2'b0, n_x} - pred;
        // the context's first model: (12 x 3) contexts of 37 models
        case (act_class)
            4'd0: act_base = 11'd0;
            4'd1: act_base = 11'd111;
            4'd2: act_base = 11'd222;
            4'd3: act_base = 11'd333;
            4'd4: act_base = 11'd444;
            4'd5: act_base = 11'd555;
            4'd6: act_base = 11'd666;
            4'd7: act_base = 11'd777;
            4'd8: act_base = 11'd888;
            4'd9: act_base = 11'd999;
            4'd10: act_base = 11'd1110;
            default: act_base = 11'd1221;
        endcase
        base = act_base + ((bright_class == 0) ? 11'd0 : (bright_class == 1) ? 11'd37 : 11'd74);
    end

    // |v| - 1 and its bit length
    logic [16:0] mag_in;
    logic [4:0]  n_in;
    always_comb begin
        mag_in = res[17] ? 17'(-res - 18'sd1) : 17'(res - 18'sd1);
        n_in = 0;
        for (int i = 0; i < 17; ++i)
            if (mag_in[i]) n_in = 5'(i + 1);
    end

    // ---- the sample being coded and its next bit ---------------------------
    typedef enum logic [2:0] {S_ZERO, S_SIGN, S_MZERO, S_LEN, S_TOP, S_DIR} step_t;
    logic        f_valid, f_nz, f_neg, f_last;
    logic [16:0] f_mag;
    logic [4:0]  f_n;
    logic [10:0] f_base;    // the context's first model
    step_t       st;
    logic [4:0]  si;        // len's i, or the direct bit's place
    logic        flushing;
    logic [1:0]  fl;        // the flush's clock

    logic        bit_v, direct, last_bit;
    step_t       st_next;
    logic [4:0]  si_next;
    logic [5:0]  idx_next;  // the next bit's model within the context
    always_comb begin
        bit_v = 0;
        direct = 0;
        last_bit = 0;
        st_next = st;
        si_next = si;
        case (st)
            S_ZERO: begin
                bit_v = f_nz;
                last_bit = !f_nz;
                st_next = S_SIGN;
            end
            S_SIGN: begin
                bit_v = f_neg;
                st_next = S_MZERO;
            end
            S_MZERO: begin
                bit_v = f_mag != 0;
                last_bit = f_mag == 0;
                st_next = S_LEN;
                si_next = 1;
            end
            S_LEN: begin
                bit_v = si < f_n;
                if (si < f_n && 32'(si) + 1 < MAG_BITS) begin
                    si_next = si + 5'd1;
                end else if (f_n >= 2) begin
                    st_next = S_TOP;
                end else begin
                    last_bit = 1;
                end
            end
            S_TOP: begin
                bit_v = f_mag[f_n - 5'd2];
                if (f_n > 2) begin
                    st_next = S_DIR;
                    si_next = f_n - 5'd3;
                end else begin
                    last_bit = 1;
                end
            end
            default: begin  // S_DIR
                direct = 1;
                bit_v = f_mag[si];
                if (si == 0) last_bit = 1;
                else si_next = si - 5'd1;
            end
        endcase
        case (st_next)
            S_ZERO: idx_next = 0;
            S_SIGN: idx_next = 1;
            S_MZERO: idx_next = 2;
            S_LEN: idx_next = 6'(si_next) + 6'd2;
            S_TOP: idx_next = 6'(f_n) + 6'd18;
            default: idx_next = 0;  // a direct bit: no model
        endcase
    end

    // The sample taken waits in a register of its own (q_*) until the
    // coder takes it: a tile's last bit is followed by its flush, not by
    // a sample.
    logic        q_valid, q_nz, q_neg, q_last, q_first, q_wide;
    logic [16:0] q_mag;
    logic [4:0]  q_n;
    logic [10:0] q_base;
    logic coding, move;
    always_comb begin
        coding = f_valid && !flushing;
        move = q_valid && !flushing && (!f_valid || (last_bit && !f_last));
        go = n_valid && (!q_valid || move);
        in_ready = !n_valid || go;
        take = in_valid && in_ready;
    end

    // ---- the models --------------------------------------------------------
    // The bit being coded reads its model from p_reg, read in the clock
    // before from the model's address then (a_reg), or taken from the
    // bit just coded when that wrote the same model.
    logic [11:0] prob [NM];
    logic [NM-1:0] pvalid;
    logic [10:0] a_reg, a_next;
    logic [11:0] p, p_reg, p_new, p_next;
    always_comb begin
        p = p_reg;
        a_next = move ? q_base : f_base + 11'(idx_next);
        if (move && q_first)
            p_next = 12'd2048;  // a tile's fresh models
        else if (coding && !direct && a_next == a_reg)
            p_next = p_new;
        else
            p_next = pvalid[a_next] ? prob[a_next] : 12'd2048;
    end

    // ---- the range coder ---------------------------------------------------
    logic [32:0] low;
    logic [31:0] range;
    logic [7:0]  cache;
    logic [31:0] held, nbytes;

    // One shift of the low word (`Encoder::shift_low`), twice in a clock:
    // when its top byte is settled (below 0xFF000000, or carried past
    // 2^32) the cached byte plus the carry goes out, then the held 0xFF
    // bytes plus the carry; the low word's top byte is cached.
    logic [31:0] bound, range1, range2;
    logic [32:0] low1, low_a, low_b, low_c;
    logic [7:0]  cache_a, cache_b, cache_c;
    logic [31:0] held_a, held_b, held_c;
    logic        sh1, sh2, out1, out2;
    logic [7:0]  head1, head2, fill1, fill2;
    logic [31:0] count1, count2;
    logic [31:0] held_m1, held_p1, held_p2, nbytes_h, nbytes_h1, nbytes_c;
    always_comb begin
        held_m1 = held - 32'd1;
        held_p1 = held + 32'd1;
        held_p2 = held + 32'd2;
        nbytes_h = nbytes + held;
        nbytes_h1 = nbytes + held + 32'd1;
    end
    always_comb begin
        bound = 32'(range[31:12]) * 32'(p);
        p_new = p;
        if (direct) begin
            range1 = range >> 1;
            low1 = bit_v ? low + {1'b0, range1} : low;
        end else if (bit_v) begin
            low1 = low + {1'b0, bound};
            range1 = range - bound;
            p_new = p - (p >> 4);
        end else begin
            low1 = low;
            range1 = bound;
            p_new = p + ((12'd4095 - p + 12'd1) >> 4);
        end
        if (flushing) begin
            low1 = low;
            range1 = range;
        end
        // renormalisation: up to two shifts while coding, two, two and
        // one over the flush's three clocks (`Encoder::finish`)
        sh1 = flushing || range1 < 32'h01000000;
        range2 = range1 << 8;
        sh2 = flushing ? fl != 2 : (sh1 && range2 < 32'h01000000);
        // the first shift (the held counts' sums are of registers alone:
        // off the path through the multiply)
        out1 = (low1 < 33'h0ff000000) || low1[32];
        head1 = cache + {7'b0, low1[32]};
        fill1 = 8'hff + {7'b0, low1[32]};
        count1 = held_m1;
        low_a = {1'b0, low1[23:0], 8'b0};
        cache_a = out1 ? low1[31:24] : cache;
        held_a = out1 ? 32'd1 : held_p1;
        // the second, after the first
        out2 = (low_a < 33'h0ff000000) || low_a[32];
        head2 = cache_a + {7'b0, low_a[32]};
        fill2 = 8'hff + {7'b0, low_a[32]};
        count2 = out1 ? 32'd0 : held;
        low_b = {1'b0, low_a[23:0], 8'b0};
        cache_b = out2 ? low_a[31:24] : cache_a;
        held_b = out2 ? 32'd1 : out1 ? 32'd2 : held_p2;
        // the coder after this clock
        low_c = sh2 ? low_b : sh1 ? low_a : low1;
        cache_c = sh2 ? cache_b : sh1 ? cache_a : cache;
        held_c = sh2 ? held_b : sh1 ? held_a : held;
        // bytes out: the first shift's held bytes, or, when the second
        // shift sends, one more (it sends one after the first sent, or
        // the held ones and its own)
        nbytes_c = (sh2 && out2) ? nbytes_h1 : (sh1 && out1) ? nbytes_h : nbytes;
    end

    // ---- the tile's samples and widths ---------------------------------------
    logic [31:0] nsamp;
    logic        wide;

    logic [31:0] raw_len;
    always_comb raw_len = wide ? {nsamp[30:0], 1'b0} : nsamp;

    always_ff @(posedge clk) begin
        out_valid <= 0;
        out_done <= 0;
        if (rst) begin
            f_valid <= 0;
            q_valid <= 0;
            n_valid <= 0;
            flushing <= 0;
            col <= 0;
            row0 <= 1;
        end else begin
            // the bit: the model, the coder, the bytes out
            if (coding || flushing) begin
                if (coding && !direct) begin
                    prob[a_reg] <= p_new;
                    pvalid[a_reg] <= 1'b1;
                end
                low <= low_c;
                range <= sh2 ? range2 << 8 : sh1 ? range2 : range1;
                cache <= cache_c;
                held <= held_c;
                nbytes <= nbytes_c;
                out_valid <= {sh1 && out1, sh2 && out2};
                out_head <= {head1, head2};
                out_fill <= {fill1, fill2};
                out_count <= {count1, count2};
            end
            if (coding) begin
                st <= st_next;
                si <= si_next;
                if (last_bit) begin
                    f_valid <= 0;
                    if (f_last) begin
                        flushing <= 1;
                        fl <= 0;
                    end
                end
            end
            if (flushing) begin
                fl <= fl + 2'd1;
                if (fl == 2) begin
                    flushing <= 0;
                    out_done <= 1;
                    out_bytes <= nbytes_c;
                    out_wide <= wide;
                    out_context <= nbytes_c < raw_len;
                end
            end
            // the next sample in
            if (take) begin
                line[AW'(c0)] <= in_sample;
                left <= in_sample;
                if (c1 >= width || in_last) begin
                    col <= 0;
                    row0 <= in_last;
                    up_l <= 0;
                    up_x <= (width == 1) ? in_sample : line[0];
                end else begin
                    col <= c1;
                    row0 <= r0;
                    up_l <= up_x;
                    up_x <= up_r;
                end
                n_x <= in_sample;
                n_a <= na;
                n_b <= nb;
                n_c <= nc;
                n_d <= nd;
                n_first <= in_first;
                n_last <= in_last;
            end
            if (take) n_valid <= 1;
            else if (go) n_valid <= 0;
            if (go) begin
                q_nz <= res != 0;
                q_neg <= res[17];
                q_mag <= mag_in;
                q_n <= n_in;
                q_base <= base;
                q_last <= n_last;
                q_first <= n_first;
                q_wide <= n_x > 16'd255;
            end
            if (go) q_valid <= 1;
            else if (move) q_valid <= 0;
            if (coding || move) begin
                a_reg <= a_next;
                p_reg <= p_next;
            end
            // the waiting sample into the coder
            if (move) begin
                f_valid <= 1;
                f_nz <= q_nz;
                f_neg <= q_neg;
                f_mag <= q_mag;
                f_n <= q_n;
                f_base <= q_base;
                f_last <= q_last;
                st <= S_ZERO;
                si <= 0;
                nsamp <= (q_first ? 32'd0 : nsamp) + 32'd1;
                wide <= (q_first ? 1'b0 : wide) | q_wide;
                if (q_first) begin
                    // a fresh coder and fresh models
                    pvalid <= '0;
                    low <= 0;
                    range <= 32'hffffffff;
                    cache <= 0;
                    held <= 32'd1;
                    nbytes <= 0;
                end
            end
        end
    end
endmodule
