//! libm's `sincos` (0.2.16, a port of musl's), emitted inline by the JIT:
//! the same operations in the same order, so a compiled tape gives the bits of
//! the host's libm (which the interpreter and the generated kernels call).
//!
//! Why inline: a host call clobbers every SSE register, so every value live
//! across it was spilled and reloaded; the generated kernels, compiled by LLVM,
//! inline the same libm code. On omni_caster's step with F_p (five sincos) the
//! JIT went from 1.47-1.51x to 1.25-1.38x the generated kernel.
//!
//! libm's branches are kept as blocks: no reduction below pi/4; one round of
//! Cody-Waite reduction by a fixed multiple of pi/2 up to 9 pi/4, except near
//! the multiples where it cancels; up to three rounds (computed together and
//! selected, a cold block) up to 2^20 pi/2; libm's multi-precision reduction,
//! infinities and NaN through the host call the caller emits (cold).
use cranelift_codegen::ir::condcodes::IntCC;
use cranelift_codegen::ir::{types, Block, BlockArg, InstBuilder, MemFlagsData, Value};
use cranelift_frontend::FunctionBuilder;

/// libm's constants, by their bit patterns (as its comments give them).
const fn bits(b: [u64; 6]) -> [f64; 6] {
    let mut out = [0.0; 6];
    let mut k = 0;
    while k < 6 {
        out[k] = f64::from_bits(b[k]);
        k += 1;
    }
    out
}
const TO_INT: f64 = 1.5 / f64::EPSILON;
const INV_PIO2: f64 = f64::from_bits(0x3fe45f306dc9c883);
const PIO2_1: f64 = f64::from_bits(0x3ff921fb54400000);
const PIO2_1T: f64 = f64::from_bits(0x3dd0b4611a626331);
const PIO2_2: f64 = f64::from_bits(0x3dd0b4611a600000);
const PIO2_2T: f64 = f64::from_bits(0x3ba3198a2e037073);
const PIO2_3: f64 = f64::from_bits(0x3ba3198a2e000000);
const PIO2_3T: f64 = f64::from_bits(0x397b839a252049c1);
const S: [f64; 6] = bits([
    0xbfc5555555555549,
    0x3f8111111110f8a6,
    0xbf2a01a019c161d5,
    0x3ec71de357b1fe7d,
    0xbe5ae5e68a2b9ceb,
    0x3de5d93a5acfd57c,
]);
const C: [f64; 6] = bits([
    0x3fa555555555554c,
    0xbf56c16c16c15177,
    0x3efa01a019cb1590,
    0xbe927e4f809c52ad,
    0x3e21ee9ebdb4b1c4,
    0xbda8fae9be8838d4,
]);

/// Shorthands over the builder, to keep the formulas readable.
struct E<'b, 'f>(&'b mut FunctionBuilder<'f>);

impl E<'_, '_> {
    fn k(&mut self, c: f64) -> Value {
        self.0.ins().f64const(c)
    }
    fn add(&mut self, x: Value, y: Value) -> Value {
        self.0.ins().fadd(x, y)
    }
    fn sub(&mut self, x: Value, y: Value) -> Value {
        self.0.ins().fsub(x, y)
    }
    fn mul(&mut self, x: Value, y: Value) -> Value {
        self.0.ins().fmul(x, y)
    }
    fn mulk(&mut self, x: Value, c: f64) -> Value {
        let c = self.k(c);
        self.mul(x, c)
    }
    fn sel(&mut self, c: Value, x: Value, y: Value) -> Value {
        self.0.ins().select(c, x, y)
    }
    fn cmp(&mut self, cc: IntCC, x: Value, c: i64) -> Value {
        self.0.ins().icmp_imm_u(cc, x, c)
    }
    /// The biased exponent of a double.
    fn exponent(&mut self, x: Value) -> Value {
        let bits = self.0.ins().bitcast(types::I64, MemFlagsData::new(), x);
        let e = self.0.ins().ushr_imm_u(bits, 52);
        self.0.ins().band_imm_u(e, 0x7ff)
    }
    fn enter(&mut self, block: Block) {
        self.0.switch_to_block(block);
        self.0.seal_block(block);
    }
    /// The first round of reduction by f pi/2, good to 85 bits: (r, w, y0).
    fn first_round(&mut self, x: Value, f: Value) -> (Value, Value, Value) {
        let fp = self.mulk(f, PIO2_1);
        let r = self.sub(x, fp);
        let w = self.mulk(f, PIO2_1T);
        let y0 = self.sub(r, w);
        (r, w, y0)
    }
    /// (k_sin(x, y, iy), k_cos(x, y)); `reduced` is iy = 1 (x + y is a
    /// reduced argument with tail y).
    fn kernels(&mut self, x: Value, y: Value, reduced: bool) -> (Value, Value) {
        let z = self.mul(x, x);
        let w = self.mul(z, z);
        // r = S2 + z (S3 + z S4) + z w (S5 + z S6)
        let t = self.mulk(z, S[3]);
        let s3 = self.k(S[2]);
        let t = self.add(s3, t);
        let t = self.mul(z, t);
        let s2 = self.k(S[1]);
        let r = self.add(s2, t);
        let u = self.mulk(z, S[5]);
        let s5 = self.k(S[4]);
        let u = self.add(s5, u);
        let zw = self.mul(z, w);
        let u = self.mul(zw, u);
        let r = self.add(r, u);
        let v = self.mul(z, x);
        let sin = if reduced {
            // x - ((z (0.5 y - v r) - y) - v S1)
            let hy = self.mulk(y, 0.5);
            let vr = self.mul(v, r);
            let t = self.sub(hy, vr);
            let t = self.mul(z, t);
            let t = self.sub(t, y);
            let vs1 = self.mulk(v, S[0]);
            let t = self.sub(t, vs1);
            self.sub(x, t)
        } else {
            // x + v (S1 + z r)
            let t = self.mul(z, r);
            let s1 = self.k(S[0]);
            let t = self.add(s1, t);
            let t = self.mul(v, t);
            self.add(x, t)
        };
        // r = z (C1 + z (C2 + z C3)) + w w (C4 + z (C5 + z C6))
        let t = self.mulk(z, C[2]);
        let c2 = self.k(C[1]);
        let t = self.add(c2, t);
        let t = self.mul(z, t);
        let c1 = self.k(C[0]);
        let t = self.add(c1, t);
        let t = self.mul(z, t);
        let u = self.mulk(z, C[5]);
        let c5 = self.k(C[4]);
        let u = self.add(c5, u);
        let u = self.mul(z, u);
        let c4 = self.k(C[3]);
        let u = self.add(c4, u);
        let w4 = self.mul(w, w);
        let u = self.mul(w4, u);
        let r = self.add(t, u);
        // (1 - hz) + (((1 - (1 - hz)) - hz) + (z r - x y))
        let hz = self.mulk(z, 0.5);
        let one = self.k(1.0);
        let wc = self.sub(one, hz);
        let t = self.sub(one, wc);
        let t = self.sub(t, hz);
        let zr = self.mul(z, r);
        let xy = self.mul(x, y);
        let zr = self.sub(zr, xy);
        let t = self.add(t, zr);
        (sin, self.add(wc, t))
    }
    /// One more round of medium-size reduction: (r, w, y0) from r.
    fn round(&mut self, f: Value, r: Value, p: f64, pt: f64) -> (Value, Value, Value) {
        let t = r;
        let w = self.mulk(f, p);
        let r = self.sub(t, w);
        let fpt = self.mulk(f, pt);
        let d = self.sub(t, r);
        let d = self.sub(d, w);
        let w = self.sub(fpt, d);
        let y0 = self.sub(r, w);
        (r, w, y0)
    }
}

impl E<'_, '_> {
    /// The medium range (up to 2^20 pi/2): rint(x / (pi/2))
    /// (round-to-nearest), then a second and a third round where the first
    /// cancelled more than 16, then 49, bits (rare enough to compute both and
    /// select); jumps to `quadrant` with (n, y0, y1).
    fn medium_reduction(&mut self, x: Value, ix: Value, quadrant: Block) {
        use IntCC::SignedGreaterThan;
        let e = self;
        let tmp = e.mulk(x, INV_PIO2);
        let to_int = e.k(TO_INT);
        let tmp = e.add(tmp, to_int);
        let f = e.sub(tmp, to_int);
        let (r1, w1, y01) = e.first_round(x, f);
        let ex = e.0.ins().ushr_imm_u(ix, 20);
        let cancelled = |e: &mut E, y0: Value, bits: i64| {
            let ey = e.exponent(y0);
            let lost = e.0.ins().isub(ex, ey);
            e.cmp(SignedGreaterThan, lost, bits)
        };
        let second = cancelled(e, y01, 16);
        let (r2, w2, y02) = e.round(f, r1, PIO2_2, PIO2_2T);
        let third = cancelled(e, y02, 49);
        let third = e.0.ins().band(third, second);
        let (r3, w3, y03) = e.round(f, r2, PIO2_3, PIO2_3T);
        let pick = |e: &mut E, a: Value, b: Value, c: Value| {
            let bc = e.sel(third, c, b);
            e.sel(second, bc, a)
        };
        let r = pick(e, r1, r2, r3);
        let w = pick(e, w1, w2, w3);
        let y0 = pick(e, y01, y02, y03);
        let d = e.sub(r, y0);
        let y1 = e.sub(d, w);
        e.0.ins().jump(quadrant, &[f, y0, y1].map(BlockArg::Value));
    }

    /// The quadrant n & 3 of the reduced argument (y0, y1): (s, c), (c, -s),
    /// (-s, -c), (-c, s); jumps to `done` with (sin, cos).
    fn by_quadrant(&mut self, quadrant: Block, done: Block) {
        use IntCC::NotEqual;
        let e = self;
        let [f, y0, y1] = [0, 1, 2].map(|k| e.0.block_params(quadrant)[k]);
        let (s, c) = e.kernels(y0, y1, true);
        let n = e.0.ins().fcvt_to_sint_sat(types::I64, f);
        let odd = e.0.ins().band_imm_u(n, 1);
        let odd = e.cmp(NotEqual, odd, 0);
        let half = e.0.ins().band_imm_u(n, 2);
        let flip_sin = e.cmp(NotEqual, half, 0);
        let next = e.0.ins().iadd_imm_u(n, 1);
        let next = e.0.ins().band_imm_u(next, 2);
        let flip_cos = e.cmp(NotEqual, next, 0);
        let sin = e.sel(odd, c, s);
        let cos = e.sel(odd, s, c);
        let (neg_sin, neg_cos) = (e.0.ins().fneg(sin), e.0.ins().fneg(cos));
        let sin = e.sel(flip_sin, neg_sin, sin);
        let cos = e.sel(flip_cos, neg_cos, cos);
        e.0.ins()
            .jump(done, &[BlockArg::Value(sin), BlockArg::Value(cos)]);
    }
}

/// Emits the blocks computing (sin x, cos x) and switches to the block
/// where they are the parameters; `host` emits the call for the arguments
/// libm reduces with its multi-precision path (and infinities and NaN).
pub fn emit(
    b: &mut FunctionBuilder,
    x: Value,
    host: impl FnOnce(&mut FunctionBuilder, Value) -> (Value, Value),
) -> (Value, Value) {
    use IntCC::{NotEqual, SignedLessThan};
    use IntCC::{UnsignedGreaterThanOrEqual as Ge, UnsignedLessThanOrEqual as Le};
    let mut e = E(b);
    let blocks = [(); 6].map(|_| e.0.create_block());
    let [small, reduce, fixed, medium, large, quadrant] = blocks;
    let done = e.0.create_block();
    for block in [done, done] {
        e.0.append_block_param(block, types::F64);
    }
    for _ in 0..3 {
        e.0.append_block_param(quadrant, types::F64);
    }
    for block in [medium, large] {
        e.0.set_cold_block(block);
    }
    let bits = e.0.ins().bitcast(types::I64, MemFlagsData::new(), x);
    let high = e.0.ins().ushr_imm_u(bits, 32);
    let ix = e.0.ins().band_imm_u(high, 0x7fff_ffff);
    let below_pi_4 = e.cmp(Le, ix, 0x3fe9_21fb);
    e.0.ins().brif(below_pi_4, small, &[], reduce, &[]);

    // |x| ~< pi/4: no reduction; below 2^-27 sqrt 2, (x, 1)
    e.enter(small);
    let zero = e.k(0.0);
    let (sin, cos) = e.kernels(x, zero, false);
    let tiny = e.cmp(IntCC::UnsignedLessThan, ix, 0x3e46_a09e);
    let one = e.k(1.0);
    let sin = e.sel(tiny, x, sin);
    let cos = e.sel(tiny, one, cos);
    e.0.ins()
        .jump(done, &[BlockArg::Value(sin), BlockArg::Value(cos)]);

    // |x| ~<= 9 pi/4, away from the multiples of pi/2 where one round
    // cancels: a fixed multiple 1..4 of pi/2, one round
    e.enter(reduce);
    let low = e.0.ins().band_imm_u(ix, 0xfffff);
    let not_near_pi = e.cmp(NotEqual, low, 0x921fb);
    let not_near_3pi_2 = e.cmp(NotEqual, ix, 0x4012_d97c);
    let not_near_2pi = e.cmp(NotEqual, ix, 0x4019_21fb);
    let below_7pi_4 = e.cmp(Le, ix, 0x4015_fdbc);
    let fixed_34 = e.sel(below_7pi_4, not_near_3pi_2, not_near_2pi);
    let below_9pi_4 = e.cmp(Le, ix, 0x401c_463b);
    let fixed_34 = e.0.ins().band(below_9pi_4, fixed_34);
    let below_5pi_4 = e.cmp(Le, ix, 0x400f_6a7a);
    let is_fixed = e.sel(below_5pi_4, not_near_pi, fixed_34);
    e.0.ins().brif(is_fixed, fixed, &[], medium, &[]);

    e.enter(fixed);
    let multiple = |e: &mut E, k: f64| {
        let (pos, neg) = (e.k(k), e.k(-k));
        let negative = e.cmp(SignedLessThan, bits, 0);
        e.sel(negative, neg, pos)
    };
    let (f1, f2) = (multiple(&mut e, 1.0), multiple(&mut e, 2.0));
    let (f3, f4) = (multiple(&mut e, 3.0), multiple(&mut e, 4.0));
    let below_3pi_4 = e.cmp(Le, ix, 0x4002_d97c);
    let f12 = e.sel(below_3pi_4, f1, f2);
    let f34 = e.sel(below_7pi_4, f3, f4);
    let f = e.sel(below_5pi_4, f12, f34);
    let (r, w, y0) = e.first_round(x, f);
    let d = e.sub(r, y0);
    let y1 = e.sub(d, w);
    e.0.ins().jump(quadrant, &[f, y0, y1].map(BlockArg::Value));

    // up to 2^20 pi/2: rint(x / (pi/2)) (round-to-nearest), then a second
    // and a third round where the first cancelled more than 16, then 49,
    // bits (rare enough to compute both and select)
    e.enter(medium);
    let beyond = e.cmp(Ge, ix, 0x4139_21fb);
    let in_range = e.0.create_block();
    e.0.ins().brif(beyond, large, &[], in_range, &[]);
    e.enter(in_range);
    e.medium_reduction(x, ix, quadrant);

    e.enter(large);
    let (sin, cos) = host(e.0, x);
    e.0.ins()
        .jump(done, &[BlockArg::Value(sin), BlockArg::Value(cos)]);

    e.enter(quadrant);
    e.by_quadrant(quadrant, done);

    e.enter(done);
    (e.0.block_params(done)[0], e.0.block_params(done)[1])
}
