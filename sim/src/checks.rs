//! Self-checks that run unchanged on the host (`cargo test`) and inside QEMU
//! (`qemu-tests`). Each drives the real drivers against emulated chips or
//! runs the algorithms on seeded data. The digest checks hash every output
//! bit and compare with the committed golden values in
//! `sim/vectors/digests.in`; since host and target both must match
//! them, their results are bit-identical.

use core::cell::RefCell;

use crate::with_bus;

use crate::{
    board_array, board_drivers, emu_device, Adxrs453Model, BoardDrivers, Chip, CsLine, EmuBus,
    EmuDelay, Fault, Icm42688Model, Mount, NoiseParams, RateProfile, Rng,
};
use gyro_array::algo::fusion::{
    AdaptiveConfig, AxisState, Denominator, Fusion, GrubbsConfig, MemoryConfig, Method, Normaliser,
    SupportConfig,
};
use gyro_array::algo::static_cal::CalRecord;
use gyro_array::drivers::adxrs453::{self, Adxrs453, OnAxis};
use gyro_array::drivers::icm42688::{self, Config, Icm42688};
use gyro_array::drivers::Gyro;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::{flag, Output, Pipeline, PipelineConfig};

/// `math::sqrtf` against `libm::sqrtf` over 0, subnormals, every binade
/// of the normal range (a spread of mantissas in each) and ∞; a negative
/// input must give NaN in both. On the board `sqrtf` is the FPU's
/// instruction, so this is what makes it the same function.
pub fn sqrt_matches_libm() -> bool {
    use gyro_array::algo::math::sqrtf;
    let same = |x: f32| sqrtf(x).to_bits() == libm::sqrtf(x).to_bits();
    let mut ok = same(0.0) && same(-0.0) && same(f32::INFINITY) && same(f32::MIN_POSITIVE);
    ok &= sqrtf(-1.0).is_nan() && libm::sqrtf(-1.0).is_nan();
    let mut rng = Rng::new(3);
    for e in 0u32..255 {
        for _ in 0..16 {
            let bits = (e << 23) | (rng.next_u32() & 0x007f_ffff);
            ok &= same(f32::from_bits(bits));
        }
    }
    ok
}

/// Golden digests (generated on the host, checked on both sides).
pub mod golden {
    include!("../vectors/digests.in");
}

/// FNV-1a over 32-bit words.
#[derive(Clone, Copy)]
pub struct Digest(pub u64);

impl Digest {
    /// Empty digest.
    pub const fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    /// Mix one word.
    pub fn word(&mut self, w: u32) {
        for b in w.to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
    /// Mix an f32's bits.
    pub fn f32(&mut self, v: f32) {
        self.word(v.to_bits())
    }
}

impl Default for Digest {
    fn default() -> Self {
        Self::new()
    }
}

/// Digest of the Allan path on seeded integer data: streaming OADEV (10
/// octave τ, every 997th sample) and two E-DAVARs (segmented, centred
/// spectral) over a variance step, every published surface row.
/// Exercises the integer sums, the soft-float f64 output, microfft and the
/// entropies, so host and Cortex-M4 must agree bit for bit.
pub fn allan_digest() -> u64 {
    use gyro_array::algo::allan::stream::StreamAdev;
    use gyro_array::algo::davar::{
        Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold,
    };
    let mut d = Digest::new();
    let mut rng = Rng::new(77);
    let Ok(mut adev) = StreamAdev::<10, 1024>::new() else {
        return 0;
    };
    let cfg = |entropy, placement| DavarConfig {
        lambda1: 256,
        lambda2: 512,
        l_init: 512,
        delta_l: 32,
        step: StepMode::Constant,
        entropy,
        threshold: Threshold::Auto { p_fa: 0.01 },
        placement,
        tau_octaves: 1,
    };
    let (Ok(mut a), Ok(mut b)) = (
        Davar::<512, 19, 7>::new(cfg(EntropyKind::Temporal, Placement::Segmented)),
        Davar::<512, 19, 7>::new(cfg(EntropyKind::Spectral, Placement::Centred)),
    ) else {
        return 0;
    };
    for i in 0..6000u32 {
        let s = if (2000..4000).contains(&i) {
            300.0
        } else {
            150.0
        };
        let x = (s * rng.gaussian()) as i32 + 4000;
        let _ = adev.push(x);
        if i % 997 == 996 {
            for j in 0..10 {
                if let Ok(p) = adev.point(j, 1.0 / 1024.0, 0.001) {
                    let bits = p.avar.to_bits();
                    d.word(bits as u32);
                    d.word((bits >> 32) as u32);
                }
            }
        }
        for dv in [&mut a, &mut b] {
            if let (Ok(Some(_)), Some(e)) = (dv.push(x), dv.estimate()) {
                {
                    d.word(e.t as u32);
                    d.word(e.start as u32);
                    d.word(e.len as u32);
                    d.f32(e.score);
                    d.f32(e.threshold);
                    for v in e.avar {
                        d.f32(v);
                    }
                }
            }
        }
    }
    d.0
}

/// `k` of the seed-scaled variant (chosen in `fusion-eval`, see README).
pub const SCALED_K: f32 = 11.0;

/// Digest of the noise-qualification path in f32 (the board's types) on
/// seeded data: the noise-health self-test, a db5 decomposition with
/// BayesShrink, an EMD and a Burg AR(4) fit. Host and Cortex-M4 must agree
/// bit for bit.
pub fn qualify_digest() -> u64 {
    use gyro_array::algo::qualify::ar::burg;
    use gyro_array::algo::qualify::emd::{emd, work_len, EmdConfig};
    use gyro_array::algo::qualify::wavelet::{bayes_shrink, wavedec, waverec, DB5};
    use gyro_array::pipeline::selftest::{noise_health, BLOCK};
    const N: usize = 512;
    let mut d = Digest::new();
    let mut rng = Rng::new(2718);
    let mut block = [0.0f32; BLOCK];
    for (i, v) in block.iter_mut().enumerate() {
        *v = 0.1 * rng.gaussian() + 1e-5 * i as f32;
    }
    match noise_health(&block) {
        Ok(h) => {
            for v in [h.std_dps, h.lambda, h.hurst, h.skewness, h.kurtosis] {
                d.f32(v);
            }
        }
        Err(_) => d.word(0xdead),
    }
    let mut x = [0.0f32; N];
    for (i, v) in x.iter_mut().enumerate() {
        let t = i as f32;
        *v = libm::sinf(t * 0.31) + 0.5 * libm::sinf(t * 0.05) + 0.2 * rng.gaussian();
    }
    let mut c = [0.0f32; N + 64];
    let mut s = [0.0f32; 2 * (N + 16)];
    if let Ok(lay) = wavedec(&DB5, &x, 5, &mut c, &mut s) {
        let mut tmp = [0.0f32; N];
        let _ = bayes_shrink(&mut c, &lay, &mut tmp);
        let _ = waverec(&DB5, &c, &lay, &mut tmp, &mut s);
        for v in tmp {
            d.f32(v);
        }
    }
    let cfg = EmdConfig {
        max_imfs: 6,
        ..EmdConfig::default()
    };
    let mut rows = [0.0f32; 7 * N];
    let mut work = [0.0f32; 13 * N + 32];
    let mut idx = [0u32; N];
    debug_assert!(work.len() >= work_len(N));
    match emd(&x, &cfg, &mut rows, &mut work, &mut idx) {
        Ok(dec) => {
            d.word(dec.imfs as u32);
            let used = (dec.imfs + dec.residue as usize) * N;
            for v in rows.get(..used).unwrap_or(&[]) {
                d.f32(*v);
            }
        }
        Err(_) => d.word(0xbeef),
    }
    let mut sc = [0.0f32; 2 * N];
    if let Ok(m) = burg(&x, 4, &mut sc) {
        for v in &m.phi[..4] {
            d.f32(*v);
        }
        d.f32(m.sigma2);
    }
    d.0
}

/// Every fusion method the evaluation compares, N = 4.
pub fn methods() -> [(&'static str, Method); 8] {
    let grubbs = Some(GrubbsConfig::default());
    let seed = |clamp, g, m| {
        Method::SupportDegree(SupportConfig {
            denominator: Denominator::MSquaredMinus1,
            clamp_negative: clamp,
            grubbs: g,
            memory: m,
            normaliser: Normaliser::Instant,
        })
    };
    [
        ("mean", Method::Mean),
        ("zhang", Method::Zhang),
        ("seed-literal", seed(false, None, None)),
        ("seed-support", seed(true, None, None)),
        ("seed-grubbs", seed(true, grubbs, None)),
        (
            "seed-full",
            seed(true, grubbs, Some(MemoryConfig::default())),
        ),
        (
            "seed-scaled",
            Method::SupportDegree(SupportConfig {
                clamp_negative: true,
                grubbs,
                normaliser: Normaliser::Running {
                    k: SCALED_K,
                    alpha: 1.0 / 64.0,
                },
                ..SupportConfig::SUPPORT
            }),
        ),
        ("adaptive", Method::Adaptive(AdaptiveConfig::default())),
    ]
}

/// Fuse 512 seeded frames of 4 gyros (noise, spikes, a gyro stuck halfway)
/// with every method and hash rates, weights and rejections.
pub fn fusion_digest() -> u64 {
    let mut d = Digest::new();
    for (_, m) in methods() {
        let Ok(f) = Fusion::<4>::new(m) else { return 0 };
        let mut st = AxisState::default();
        let mut rng = Rng::new(42);
        for k in 0..512 {
            let truth = 95.0 * libm::sinf(k as f32 * 0.01);
            let mut y = [0.0f32; 4];
            for (i, v) in y.iter_mut().enumerate() {
                *v = truth + [0.05, 0.05, 0.05, 0.25][i] * rng.gaussian();
            }
            if rng.uniform() < 0.05 {
                y[1] += 20.0;
            }
            if k >= 256 {
                y[2] = 1.0;
            }
            match f.fuse(&mut st, &y, 0b1111) {
                Ok(r) => {
                    d.f32(r.rate_dps);
                    r.weights.iter().for_each(|w| d.f32(*w));
                    d.word(r.rejected as u32);
                }
                Err(_) => d.word(0xDEAD),
            }
        }
    }
    // Seed 001's local filters (entropy and covariance weights, f32 through
    // nalgebra) on the same kind of frames.
    use gyro_array::algo::mixture::{ChipFilters, ChipWeights};
    for weights in [ChipWeights::Entropy, ChipWeights::Covariance] {
        let Ok(mut cf) = ChipFilters::<4>::new([0.05, 0.05, 0.05, 0.25], 6.3, 1e-4, weights) else {
            return 0;
        };
        let mut rng = Rng::new(43);
        for k in 0..512 {
            let truth = 95.0 * libm::sinf(k as f32 * 0.01);
            let y = [0.05f32, 0.05, 0.05, 0.25].map(|s| truth + s * rng.gaussian());
            match cf.fuse(&y, 0b1111) {
                Some((r, w)) => {
                    d.f32(r);
                    w.iter().for_each(|v| d.f32(*v));
                }
                None => d.word(0xDEAD),
            }
        }
    }
    d.0
}

/// Build the board's emulated array (drivers on the emulated bus, pipeline
/// with adaptive fusion), start every gyro, then call `each(n, bus, out,
/// pipe)` for `samples` samples. `None` if the pipeline cannot be built.
fn run_board_array(
    profile: RateProfile,
    seed: u64,
    samples: u32,
    each: impl FnMut(u32, &RefCell<EmuBus<'_, 5>>, &Output<5>, &Pipeline<5>),
) -> Option<()> {
    run_board_array_from(profile, seed, samples, [Fault::None; 5], each)
}

/// Run the board's emulated array as `run_board_array` does, with a
/// fault per chip present from power-up (the fault campaign's harness).
pub fn run_board_array_from(
    profile: RateProfile,
    seed: u64,
    samples: u32,
    at_power_up: [Fault; 5],
    each: impl FnMut(u32, &RefCell<EmuBus<'_, 5>>, &Output<5>, &Pipeline<5>),
) -> Option<()> {
    run_board_array_with(profile, seed, samples, at_power_up, None, each).map(|_| ())
}

/// [`run_board_array_from`] with the ICM-42688-P array self-test of
/// `self_test` samples per phase at start-up (`None`: skipped). Returns the
/// mask of gyros that failed start-up.
pub fn run_board_array_with(
    profile: RateProfile,
    seed: u64,
    samples: u32,
    at_power_up: [Fault; 5],
    self_test: Option<u16>,
    each: impl FnMut(u32, &RefCell<EmuBus<'_, 5>>, &Output<5>, &Pipeline<5>),
) -> Option<u8> {
    run_array_from_seq(
        0,
        profile,
        seed,
        samples,
        at_power_up,
        self_test,
        None,
        None,
        each,
    )
}

/// [`run_board_array_with`] with the pipeline's first sample numbered
/// `first_seq` (the numbers before it consumed as overruns: 0 for a fresh
/// board; near `u32::MAX` for one that has run for weeks, its sequence
/// number about to wrap after 49.7 days at 1 kHz), the chips mounted as
/// `mounts` say (`None`: aligned) and the pipeline given the static
/// calibration `cal` (`None`: uncalibrated).
#[allow(clippy::too_many_arguments)]
pub fn run_array_from_seq(
    first_seq: u32,
    profile: RateProfile,
    seed: u64,
    samples: u32,
    at_power_up: [Fault; 5],
    self_test: Option<u16>,
    mounts: Option<[Mount; 5]>,
    cal: Option<&CalRecord>,
    mut each: impl FnMut(u32, &RefCell<EmuBus<'_, 5>>, &Output<5>, &Pipeline<5>),
) -> Option<u8> {
    let cs: [CsLine; 5] = Default::default();
    let mut chips = board_array(profile, seed);
    for (c, f) in chips.iter_mut().zip(at_power_up) {
        c.set_fault(f);
    }
    if let Some(m) = mounts {
        for (c, m) in chips.iter_mut().zip(m) {
            c.set_mount(m);
        }
    }
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let BoardDrivers {
        icm: [mut g0, mut g1, mut g2, mut g3],
        adx: mut g4,
    } = board_drivers(&bus, &cs);
    let mut pipe = Pipeline::<5>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    )
    .ok()?;
    if let Some(cal) = cal {
        pipe.set_calibration(Ok(cal)).ok()?;
    }
    let failed = start_array(
        [&mut g0, &mut g1, &mut g2, &mut g3],
        &mut g4,
        &mut delay,
        self_test,
        &mut pipe,
    );
    if first_seq != 0 {
        pipe.note_overrun(first_seq);
    }
    for n in 0..samples {
        with_bus(&bus, |b| b.advance(1e-3));
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let out = pipe.step(&mut gyros);
        each(n, &bus, &out, &pipe);
    }
    Some(failed)
}

/// Run the board's array for 400 samples (spikes on gyro 1 from sample 200)
/// and hash the fused output.
pub fn pipeline_digest() -> u64 {
    let profile = RateProfile {
        base_dps: [0.5, -0.2, 10.0],
        sine_dps: [0.0, 0.0, 20.0],
        sine_hz: 2.0,
        sine_start_s: 0.0,
    };
    let mut d = Digest::new();
    let ran = run_board_array(profile, 9, 400, |n, bus, out, _| {
        if n == 199 {
            with_bus(bus, |b| {
                b.chips[1].set_fault(Fault::Spikes {
                    prob: 0.2,
                    magnitude_dps: 5.0,
                })
            });
        }
        for f in out.fused.iter() {
            match f {
                Some(f) => {
                    d.f32(f.rate_dps);
                    f.weights.iter().for_each(|w| d.f32(*w));
                }
                None => d.word(0xDEAD),
            }
        }
    });
    if ran.is_some() {
        d.0
    } else {
        0
    }
}

type Bus1<'a> = RefCell<EmuBus<'a, 1>>;

fn bus_err(
    e: embedded_hal_bus::spi::DeviceError<crate::BusError, core::convert::Infallible>,
) -> crate::BusError {
    match e {
        embedded_hal_bus::spi::DeviceError::Spi(b) => b,
        embedded_hal_bus::spi::DeviceError::Cs(i) => match i {},
    }
}

fn icm_init(fault: Fault) -> Result<icm42688::SelfTest, icm42688::Error<crate::BusError>> {
    let cs: [CsLine; 1] = Default::default();
    let mut chip = Icm42688Model::new(NoiseParams::ICM42688, RateProfile::constant(3.0), 1, 80);
    chip.fault = fault;
    let bus: Bus1 = RefCell::new(EmuBus::new([Chip::Icm(chip)], &cs));
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let dev = emu_device(&bus, &cs[0]);
    let mut g = Icm42688::new(dev);
    g.init(&mut delay, Config::default())
        .map_err(|e| e.map_spi(bus_err))?;
    g.self_test(&mut delay, 50).map_err(|e| e.map_spi(bus_err))
}

fn adx_run(fault: Fault, reads: u32) -> (Result<(), adxrs453::Error<crate::BusError>>, u32, u32) {
    let cs: [CsLine; 1] = Default::default();
    let mut chip = Adxrs453Model::new(NoiseParams::ADXRS453, RateProfile::constant(-5.0), 2, 2);
    chip.fault = if fault == Fault::WrongId {
        fault
    } else {
        Fault::None
    };
    let bus: Bus1 = RefCell::new(EmuBus::new([Chip::Adx(chip)], &cs));
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let dev = emu_device(&bus, &cs[0]);
    let mut g = OnAxis::new(Adxrs453::new(dev), 2);
    let init = g.init(&mut delay).map_err(|e| e.map_spi(bus_err));
    with_bus(&bus, |b| b.chips[0].set_fault(fault));
    let (mut errors, mut wild) = (0, 0);
    for _ in 0..reads {
        with_bus(&bus, |b| b.advance(1e-3));
        match g.read_dps() {
            // 3 °/s is over 6 σ of the part's noise at 1 kHz (0.47 °/s).
            Ok(v) if (v + 5.0).abs() > 3.0 => wild += 1,
            Ok(_) => {}
            Err(_) => errors += 1,
        }
    }
    (init, errors, wild)
}

/// Run every check; `report(name, pass)` is called for each. Returns
/// (passed, failed).
pub fn run_all(report: &mut dyn FnMut(&str, bool)) -> (u32, u32) {
    let mut tally = (0u32, 0u32);
    let mut check = |name: &str, pass: bool| {
        report(name, pass);
        if pass {
            tally.0 += 1;
        } else {
            tally.1 += 1;
        }
    };
    check(
        "math: sqrtf (VSQRT on the Cortex-M4F) equals libm's bit for bit",
        sqrt_matches_libm(),
    );
    let st = icm_init(Fault::None);
    check(
        "icm42688: init and self-test on the emulated chip",
        st.is_ok_and(|s| s.ratio().iter().all(|r| (r - 1.0).abs() < 0.1)),
    );
    check(
        "icm42688: wrong WHO_AM_I is a typed error",
        icm_init(Fault::WrongId) == Err(icm42688::Error::WrongId(0x98)),
    );
    check(
        "icm42688: silent chip (MISO high) is rejected",
        icm_init(Fault::NoResponse) == Err(icm42688::Error::WrongId(0xFF)),
    );
    check(
        "icm42688: dead self-test fails on all axes",
        icm_init(Fault::DeadSelfTest) == Err(icm42688::Error::SelfTestFailed(0b111)),
    );
    // Start-up on a swaying vehicle: 20 °/s on every axis from power-up,
    // 0.2 to 5 Hz, through the array self-test (20 samples per phase, as
    // the board runs it). Every healthy chip passes; a dead one still fails.
    let mut sway_failures = 0u32;
    for (k, hz) in [0.2f32, 0.5, 1.0, 2.0, 3.5, 5.0].into_iter().enumerate() {
        let profile = RateProfile {
            base_dps: [1.0, -2.0, 3.0],
            sine_dps: [20.0, 20.0, 20.0],
            sine_hz: hz,
            sine_start_s: 0.0,
        };
        let mut faults = [Fault::None; 5];
        let dead = k % 4;
        faults[dead] = Fault::DeadSelfTest;
        let healthy = run_board_array_with(
            profile,
            40 + k as u64,
            0,
            [Fault::None; 5],
            Some(20),
            |_, _, _, _| {},
        );
        let one_dead =
            run_board_array_with(profile, 40 + k as u64, 0, faults, Some(20), |_, _, _, _| {});
        if healthy != Some(0) || one_dead != Some(1 << dead) {
            sway_failures += 1;
        }
    }
    check(
        "start-up under a 20 deg/s sway (0.2-5 Hz): healthy chips pass the array self-test, a dead one fails",
        sway_failures == 0,
    );
    let (init, errors, wild) = adx_run(Fault::None, 200);
    check(
        "adxrs453: CHK start-up, PID and 200 clean reads",
        init.is_ok() && errors == 0 && wild == 0,
    );
    let (init, ..) = adx_run(Fault::WrongId, 0);
    check(
        "adxrs453: wrong part id is a typed error",
        init == Err(adxrs453::Error::WrongId(0x5A01)),
    );
    // The first response after the fault answers a request made before it.
    let (_, errors, wild) = adx_run(Fault::ChipFault, 50);
    check(
        "adxrs453: chip fault bits surface on every read",
        errors == 49 && wild == 0,
    );
    let (_, errors, wild) = adx_run(Fault::FrameBitError { prob: 0.05 }, 2000);
    check(
        "adxrs453: single-bit frame errors are all caught by parity",
        errors > 50 && wild == 0,
    );
    check(
        "fusion: every method bit-identical to the golden digest",
        fusion_digest() == golden::FUSION,
    );
    check(
        "pipeline: emulated array bit-identical to the golden digest",
        pipeline_digest() == golden::PIPELINE,
    );
    check(
        "pipeline: saturated gyro is flagged and excluded",
        saturation_is_flagged(),
    );
    check(
        "recovery: late power-up, resets of both chip kinds, all back in use",
        recovery_comes_back(),
    );
    check(
        "recovery: a wrong chip is retried with back-off and never used",
        recovery_backs_off(),
    );
    check(
        "integrity: a corrupted range register is read back and the chip restarted",
        corrupted_config_is_restarted(),
    );
    check(
        "allan: streaming OADEV and E-DAVAR bit-identical to the golden digest",
        allan_digest() == golden::ALLAN,
    );
    check(
        "qualify: self-test, wavelets, EMD and AR in f32 bit-identical to the golden digest",
        qualify_digest() == golden::QUALIFY,
    );
    tally
}

/// Gyro 2 is unpowered at start-up and powers up at sample 300; gyro 1
/// (ICM-42688-P) resets at 800 and gyro 4 (ADXRS453) at 1200. Every sample
/// must still fuse all three axes from the others, each lost gyro must be
/// restarted and back in fusion (the reset ones within 100 samples), and
/// the counters must say so.
fn recovery_comes_back() -> bool {
    let mut ok = true;
    let mut back = [None::<u32>; 5];
    let mut counters = None;
    let ran = run_board_array_from(
        RateProfile::constant(1.0),
        5,
        3000,
        [
            Fault::None,
            Fault::None,
            Fault::PoweredOff,
            Fault::None,
            Fault::None,
        ],
        |n, bus, out, pipe| {
            match n {
                300 => {
                    with_bus(bus, |b| b.chips[2].set_fault(Fault::None));
                }
                800 => {
                    with_bus(bus, |b| b.chips[1].power_cycle());
                }
                1200 => {
                    with_bus(bus, |b| b.chips[4].power_cycle());
                }
                _ => {}
            }
            ok &= out.fused.iter().all(|f| f.is_some());
            for (i, since) in [(2, 300), (1, 800), (4, 1200)] {
                let used = out.offered.iter().any(|m| m & (1 << i) != 0);
                if n > since && used && back[i].is_none() {
                    back[i] = Some(n - since);
                }
            }
            counters = Some(*pipe.counters());
        },
    );
    let Some(c) = counters else { return false };
    #[cfg(feature = "defmt")]
    defmt::info!(
        "recovery: back after {} (late power-up), {} (ICM reset), {} (ADXRS453 reset) samples",
        back[2],
        back[1],
        back[4]
    );
    #[cfg(test)]
    std::println!(
        "recovery: back after {:?} (late power-up), {:?} (ICM reset), {:?} (ADXRS453 reset) samples; counters {:?}",
        back[2],
        back[1],
        back[4],
        c
    );
    ran.is_some()
        && ok
        && back[2].is_some()
        && back[1].is_some_and(|d| d <= 100)
        && back[4].is_some_and(|d| d <= 200)
        && c[1].resets == 1
        && c[1].restarted == 1
        && c[4].resets == 1
        && c[4].restarted == 1
        && c[2].restarted == 1
}

/// Gyro 3 answers with another part's id for 10 s: it is retried with a
/// growing back-off (a handful of attempts, not one per sample) and never
/// offered to fusion.
fn recovery_backs_off() -> bool {
    let mut never_used = true;
    let mut attempts = 0;
    let ran = run_board_array_from(
        RateProfile::constant(1.0),
        6,
        10_000,
        [
            Fault::None,
            Fault::None,
            Fault::None,
            Fault::WrongId,
            Fault::None,
        ],
        |_, _, out, pipe| {
            never_used &= out.offered.iter().all(|m| m & (1 << 3) == 0);
            attempts = pipe.counters()[3].restarts;
        },
    );
    ran.is_some() && never_used && (5..=20).contains(&attempts)
}

/// Gyro 0's range register is corrupted at sample 100 (its data change
/// scale 16×, unflagged; the fusion's gate keeps them out). The low-rate
/// read-back finds it (each gyro every 5 × 50 samples), the chip is
/// restarted, and it is back in fusion with the right scale; meanwhile the
/// fused rate stays right.
fn corrupted_config_is_restarted() -> bool {
    let mut ok = true;
    let mut counters = None;
    let ran = run_board_array(RateProfile::constant(5.0), 8, 3000, |n, bus, out, pipe| {
        if n == 100 {
            with_bus(bus, |b| b.chips[0].corrupt_config());
        }
        ok &= out
            .fused
            .iter()
            .all(|f| f.is_some_and(|f| (f.rate_dps - 5.0).abs() < 1.0));
        if n == 2999 {
            ok &= out.offered[0] & 1 != 0 && (out.rate_dps[0][0] - 5.0).abs() < 1.0;
        }
        counters = Some(pipe.counters()[0]);
    });
    ran.is_some() && ok && counters.is_some_and(|c| c.config_errors == 1 && c.restarted == 1)
}

fn saturation_is_flagged() -> bool {
    let mut ok = true;
    let ran = run_board_array(RateProfile::constant(1.0), 3, 41, |n, bus, out, pipe| {
        if n == 0 {
            with_bus(bus, |b| b.chips[3].set_fault(Fault::Saturated));
            return;
        }
        // A saturated axis is never offered, even before the flag is set.
        ok &= out.offered.iter().all(|m| m & (1 << 3) == 0);
        ok &= out
            .fused
            .iter()
            .all(|f| f.is_some_and(|f| (f.rate_dps - 1.0).abs() < 0.5));
        if n == 40 {
            ok &= pipe.health()[3].flags & flag::SATURATED != 0;
        }
    });
    ran.is_some() && ok
}

#[cfg(test)]
mod tests {
    #[test]
    fn recovery_figures() {
        assert!(super::recovery_comes_back());
        assert!(super::recovery_backs_off());
    }
}
