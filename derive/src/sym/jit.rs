//! Native code for the fast part of a [`SplitTape`](super::tape::SplitTape)
//! on x86-64 Linux: the tape's instructions translated one by one into SSE2
//! scalar instructions on the scratch slots, followed by the copy of the
//! outputs that depend on a fast input.
//!
//! A simulation with sensitivities evaluates that part at every integrator
//! stage, and the interpreter spent about 17 machine instructions per tape
//! instruction (dispatch, operand indices, store) where the translation
//! spends three (load, operate on the second operand in memory, store):
//! the tape was 42 % of a whole identification case's instructions.
//!
//! Results are bit-identical to the interpreter's: the same IEEE operations
//! in the same order (`addsd`, `subsd`, `mulsd`, `divsd`, `sqrtsd`, a sign
//! flip for the negation), and the elementary functions are called through
//! the very functions the interpreter inlines ([`Func::eval`],
//! [`super::trig::sin_cos`], `powf`, `atan2`). Where the translation is not
//! available (another target, or the system refuses executable memory) the
//! tape is interpreted.
//!
//! # Safety
//! The code reads `inputs[i]` only for the input indices of the tape, reads
//! and writes `scratch[s]` only for its slots, and writes `out[o]` only for
//! the outputs it is given; [`Native::compile`] takes the bounds those must
//! respect and refuses a tape outside them, and each call's caller asserts
//! the three buffers' lengths against the same bounds (as it does before
//! interpreting). The code keeps the System V ABI: the callee-saved
//! registers it uses are restored, and the stack is 16-byte aligned at each
//! call it makes.

use super::tape::Instr;

/// Does the environment ask for interpreted tapes
/// (`PLANTC_INTERPRET_TAPES` set to anything but empty or `0`)?
pub(crate) fn interpret_tapes() -> bool {
    std::env::var_os("PLANTC_INTERPRET_TAPES").is_some_and(|v| !v.is_empty() && v != "0")
}

/// A fast part translated to native code (see the module docs).
pub(crate) struct Native {
    #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
    code: imp::Code,
}

impl Native {
    /// Translate `instrs` and the output copies `outputs` (`(output,
    /// slot)`): `None` when the target has no translation, a slot, input or
    /// output lies outside `n_slots`, `n_inputs` or `n_outputs`, or
    /// executable memory is refused.
    #[allow(unused_variables)]
    pub(crate) fn compile(
        instrs: &[Instr],
        outputs: &[(u32, u32)],
        n_slots: usize,
        n_inputs: usize,
        n_outputs: usize,
    ) -> Option<Native> {
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        {
            if interpret_tapes() {
                return None;
            }
            let code = imp::compile(instrs, outputs, n_slots, n_inputs, n_outputs)?;
            Some(Native { code })
        }
        #[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
        {
            None
        }
    }

    /// Run the code.
    ///
    /// # Safety
    /// `inputs` holds at least `n_inputs`, `scratch` at least `n_slots` and
    /// `out` at least `n_outputs` values (the bounds given to
    /// [`Native::compile`]).
    #[inline]
    pub(crate) unsafe fn run(&self, inputs: &[f64], scratch: &mut [f64], out: &mut [f64]) {
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        {
            // SAFETY: the caller's contract above is the code's
            unsafe {
                self.code
                    .call(inputs.as_ptr(), scratch.as_mut_ptr(), out.as_mut_ptr())
            };
        }
        #[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
        {
            let _ = (inputs, scratch, out);
            unreachable!("no native code on this target");
        }
    }
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod imp {
    use super::super::expr::Func;
    use super::super::tape::Instr;

    /// The functions a `Func` instruction can call, by the index passed to
    /// [`func`].
    const FUNCS: [Func; 8] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Ln,
        Func::Abs,
        Func::Sign,
        Func::Tanh,
    ];

    extern "sysv64" fn func(x: f64, k: u32) -> f64 {
        FUNCS[k as usize].eval(x)
    }

    extern "sysv64" fn pow(a: f64, b: f64) -> f64 {
        a.powf(b)
    }

    extern "sysv64" fn atan2(y: f64, x: f64) -> f64 {
        y.atan2(x)
    }

    /// # Safety
    /// `s` and `c` point at writable `f64`s (two scratch slots).
    unsafe extern "sysv64" fn sin_cos(x: f64, s: *mut f64, c: *mut f64) {
        let (sv, cv) = super::super::trig::sin_cos(x);
        // SAFETY: the caller's contract
        unsafe {
            *s = sv;
            *c = cv;
        }
    }

    type Entry = unsafe extern "sysv64" fn(*const f64, *mut f64, *mut f64);

    /// Executable code, unmapped on drop.
    pub(super) struct Code {
        ptr: *mut libc::c_void,
        len: usize,
        entry: Entry,
    }

    // SAFETY: the mapping is read-only and executable after construction,
    // never written again; running it touches only the caller's buffers.
    unsafe impl Send for Code {}
    // SAFETY: as above: shared references only ever execute it.
    unsafe impl Sync for Code {}

    impl Code {
        /// # Safety
        /// See [`super::Native::run`].
        #[inline]
        pub(super) unsafe fn call(&self, inputs: *const f64, scratch: *mut f64, out: *mut f64) {
            // SAFETY: the caller's contract
            unsafe { (self.entry)(inputs, scratch, out) }
        }
    }

    impl Drop for Code {
        fn drop(&mut self) {
            // SAFETY: `ptr`/`len` are the mapping made in `compile`, unmapped
            // once here
            unsafe {
                libc::munmap(self.ptr, self.len);
            }
        }
    }

    /// Base registers of the memory operands.
    #[derive(Copy, Clone)]
    enum Base {
        /// `rbx`: the scratch slots.
        Scratch,
        /// `rbp`: the inputs.
        Inputs,
        /// `r12`: the outputs.
        Out,
    }

    struct Asm {
        b: Vec<u8>,
    }

    impl Asm {
        fn bytes(&mut self, b: &[u8]) {
            self.b.extend_from_slice(b);
        }

        /// ModRM (mod = 10: 32-bit displacement) with the SIB byte `r12`
        /// needs, then the displacement.
        fn modrm_disp(&mut self, reg: u8, base: Base, disp: i32) {
            let rm = match base {
                Base::Scratch => 3,
                Base::Inputs => 5,
                Base::Out => 4,
            };
            self.b.push(0b1000_0000 | (reg << 3) | rm);
            if matches!(base, Base::Out) {
                self.b.push(0x24);
            }
            self.bytes(&disp.to_le_bytes());
        }

        /// `F2 0F op` with `xmm(reg)` and `[base + disp]`: movsd load
        /// (0x10), store (0x11), sqrtsd (0x51), addsd (0x58), mulsd (0x59),
        /// subsd (0x5C), divsd (0x5E).
        fn sd(&mut self, op: u8, xmm: u8, base: Base, disp: i32) {
            self.b.push(0xF2);
            if matches!(base, Base::Out) {
                self.b.push(0x41);
            }
            self.bytes(&[0x0F, op]);
            self.modrm_disp(xmm, base, disp);
        }

        /// `movabs rax, imm64`.
        fn mov_rax(&mut self, v: u64) {
            self.bytes(&[0x48, 0xB8]);
            self.bytes(&v.to_le_bytes());
        }

        /// `call` the absolute address (through `rax`).
        fn call(&mut self, f: usize) {
            self.mov_rax(f as u64);
            self.bytes(&[0xFF, 0xD0]);
        }

        /// `lea r, [rbx + disp]` for `rdi` (7) or `rsi` (6).
        fn lea_scratch(&mut self, reg: u8, disp: i32) {
            self.bytes(&[0x48, 0x8D]);
            self.modrm_disp(reg, Base::Scratch, disp);
        }
    }

    const LOAD: u8 = 0x10;
    const STORE: u8 = 0x11;

    /// Byte offset of entry `i` of an `f64` buffer holding fewer than `n`.
    fn at(i: u32, n: usize) -> Option<i32> {
        if (i as usize) < n {
            i32::try_from(i as u64 * 8).ok()
        } else {
            None
        }
    }

    pub(super) fn compile(
        instrs: &[Instr],
        outputs: &[(u32, u32)],
        n_slots: usize,
        n_inputs: usize,
        n_outputs: usize,
    ) -> Option<Code> {
        let s = |i: u32| at(i, n_slots);
        let mut a = Asm {
            b: Vec::with_capacity(32 * (instrs.len() + outputs.len()) + 32),
        };
        // push rbp; push rbx; push r12 (the stack is then 16-byte aligned
        // for the calls); rbp = inputs, rbx = scratch, r12 = out
        a.bytes(&[0x55, 0x53, 0x41, 0x54]);
        a.bytes(&[0x48, 0x89, 0xFD, 0x48, 0x89, 0xF3, 0x49, 0x89, 0xD4]);
        for ins in instrs {
            match *ins {
                Instr::Const { dst, value } => {
                    let d = s(dst)?;
                    a.mov_rax(value.to_bits());
                    // mov [rbx + d], rax
                    a.bytes(&[0x48, 0x89]);
                    a.modrm_disp(0, Base::Scratch, d);
                }
                Instr::Input { dst, index } => {
                    let d = s(dst)?;
                    a.sd(LOAD, 0, Base::Inputs, at(index, n_inputs)?);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::Add { dst, a: x, b: y }
                | Instr::Sub { dst, a: x, b: y }
                | Instr::Mul { dst, a: x, b: y }
                | Instr::Div { dst, a: x, b: y } => {
                    let op = match ins {
                        Instr::Add { .. } => 0x58,
                        Instr::Sub { .. } => 0x5C,
                        Instr::Mul { .. } => 0x59,
                        _ => 0x5E,
                    };
                    let (d, x, y) = (s(dst)?, s(x)?, s(y)?);
                    a.sd(LOAD, 0, Base::Scratch, x);
                    a.sd(op, 0, Base::Scratch, y);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::Neg { dst, a: x } => {
                    let (d, x) = (s(dst)?, s(x)?);
                    a.sd(LOAD, 0, Base::Scratch, x);
                    // movq xmm1, rax (the sign bit); xorpd xmm0, xmm1
                    a.mov_rax(0x8000_0000_0000_0000);
                    a.bytes(&[0x66, 0x48, 0x0F, 0x6E, 0xC8]);
                    a.bytes(&[0x66, 0x0F, 0x57, 0xC1]);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::Sqrt { dst, a: x } => {
                    let (d, x) = (s(dst)?, s(x)?);
                    a.sd(0x51, 0, Base::Scratch, x);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::Pow { dst, a: x, b: y } | Instr::Atan2 { dst, y: x, x: y } => {
                    let f = match ins {
                        Instr::Pow { .. } => pow as *const () as usize,
                        _ => atan2 as *const () as usize,
                    };
                    let (d, x, y) = (s(dst)?, s(x)?, s(y)?);
                    a.sd(LOAD, 0, Base::Scratch, x);
                    a.sd(LOAD, 1, Base::Scratch, y);
                    a.call(f);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::Func { dst, f, a: x } => {
                    let k = FUNCS.iter().position(|g| *g == f)? as u32;
                    let (d, x) = (s(dst)?, s(x)?);
                    a.sd(LOAD, 0, Base::Scratch, x);
                    // mov edi, k
                    a.b.push(0xBF);
                    a.bytes(&k.to_le_bytes());
                    a.call(func as *const () as usize);
                    a.sd(STORE, 0, Base::Scratch, d);
                }
                Instr::SinCos {
                    sin_dst,
                    cos_dst,
                    a: x,
                } => {
                    let (ds, dc, x) = (s(sin_dst)?, s(cos_dst)?, s(x)?);
                    a.sd(LOAD, 0, Base::Scratch, x);
                    a.lea_scratch(7, ds);
                    a.lea_scratch(6, dc);
                    a.call(sin_cos as *const () as usize);
                }
            }
        }
        for &(o, slot) in outputs {
            let (o, slot) = (at(o, n_outputs)?, s(slot)?);
            a.sd(LOAD, 0, Base::Scratch, slot);
            a.sd(STORE, 0, Base::Out, o);
        }
        // pop r12; pop rbx; pop rbp; ret
        a.bytes(&[0x41, 0x5C, 0x5B, 0x5D, 0xC3]);
        map(&a.b)
    }

    /// Copy `code` into a fresh mapping and make it read-only executable.
    fn map(code: &[u8]) -> Option<Code> {
        let len = code.len().max(1);
        // SAFETY: a fresh anonymous private mapping of `len` bytes, written
        // within its bounds, then switched to read + execute; on any failure
        // it is unmapped and nothing else refers to it
        unsafe {
            let ptr = libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            );
            if ptr == libc::MAP_FAILED {
                return None;
            }
            std::ptr::copy_nonoverlapping(code.as_ptr(), ptr.cast::<u8>(), code.len());
            if libc::mprotect(ptr, len, libc::PROT_READ | libc::PROT_EXEC) != 0 {
                libc::munmap(ptr, len);
                return None;
            }
            let entry: Entry = std::mem::transmute::<*mut libc::c_void, Entry>(ptr);
            Some(Code { ptr, len, entry })
        }
    }
}

#[cfg(all(test, target_arch = "x86_64", target_os = "linux"))]
mod tests {
    use super::*;

    /// A split tape's fast part never holds a constant (constants are
    /// slow), so the property test in tests/native_tapes.rs cannot reach
    /// that translation: checked here on a hand-made list.
    #[test]
    fn constants_inputs_and_outputs_land_where_they_should() {
        let instrs = [
            Instr::Const {
                dst: 0,
                value: -2.5,
            },
            Instr::Input { dst: 1, index: 1 },
            Instr::Mul { dst: 2, a: 0, b: 1 },
            Instr::Const {
                dst: 3,
                value: f64::from_bits(0x7FF8_0000_0000_0123),
            },
        ];
        let native = Native {
            code: imp::compile(&instrs, &[(2, 2), (0, 3)], 4, 2, 3).expect("compiles"),
        };
        let mut scratch = [f64::NAN; 4];
        let mut out = [7.0; 3];
        // SAFETY: the buffers hold the bounds given to compile
        unsafe { native.run(&[1.0, 3.0], &mut scratch, &mut out) };
        assert_eq!(out[2], -7.5);
        assert_eq!(out[0].to_bits(), 0x7FF8_0000_0000_0123);
        assert_eq!(out[1], 7.0);
        assert_eq!(scratch[..3], [-2.5, 3.0, -7.5]);
    }

    /// Indices outside the bounds given are refused, not translated.
    #[test]
    fn out_of_bounds_is_refused() {
        let load = [Instr::Input { dst: 0, index: 2 }];
        assert!(imp::compile(&load, &[], 1, 2, 0).is_none());
        let slot = [Instr::Neg { dst: 1, a: 0 }];
        assert!(imp::compile(&slot, &[], 1, 0, 0).is_none());
        assert!(imp::compile(&[], &[(1, 0)], 1, 0, 1).is_none());
    }
}
