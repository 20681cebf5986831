//! Simulator backend: a [`Plant`] integrated by fixed-step RK4 between samples.

use crate::backend::{Backend, BackendError, EncoderMap, Tick};
use crate::integrate::Rk4Scratch;
use crate::pacer::Pacer;
use crate::plant::Plant;
use crate::prng::SplitMix64;
use std::f64::consts::PI;

/// Optional seeded noise of the simulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimNoise {
    /// PRNG seed.
    pub seed: u64,
    /// Standard deviation of measurement noise added before quantisation, in counts.
    pub counts_std: f64,
    /// Standard deviation of a disturbance voltage added to the applied input (V).
    pub volts_std: f64,
}

/// Simulator settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// RK4 sub-steps per sample (default 10).
    pub substeps: u32,
    /// Encoder counts per revolution for every position state (default 4096).
    pub counts_per_rev: f64,
    /// Optional noise; `None` = noise free.
    pub noise: Option<SimNoise>,
    /// Input delay in whole samples (default 0).
    pub input_delay_samples: usize,
    /// Sleep to absolute deadlines instead of running in virtual time (default false).
    pub real_time: bool,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            substeps: 10,
            counts_per_rev: 4096.0,
            noise: None,
            input_delay_samples: 0,
            real_time: false,
        }
    }
}

/// The simulator backend. The state's first half are positions (angles) read
/// through quantised encoders; its single motor input is the plant's first input,
/// saturated to the plant's limits and held between samples (zero-order hold).
pub struct SimBackend {
    plant: Box<dyn Plant + Send>,
    config: SimConfig,
    x: Vec<f64>,
    u: Vec<f64>,
    delay: Vec<f64>,
    delay_pos: usize,
    scratch: Rk4Scratch,
    maps: Vec<EncoderMap>,
    rng: Option<SplitMix64>,
    pacer: Option<Pacer>,
    period: f64,
    t: f64,
    started: bool,
    first: bool,
    closed: bool,
    last_written: f64,
}

impl SimBackend {
    /// A simulator of `plant` starting at state `x0`.
    pub fn new(
        plant: Box<dyn Plant + Send>,
        x0: Vec<f64>,
        config: SimConfig,
    ) -> Result<Self, BackendError> {
        let n = plant.state_names().len();
        if x0.len() != n || n == 0 || n & 1 == 1 {
            return Err(BackendError::InvalidConfig(format!(
                "sim: x0 has {} entries, plant has {} states (need an even, equal number)",
                x0.len(),
                n
            )));
        }
        if plant.input_names().is_empty() || plant.input_limits().len() != plant.input_names().len()
        {
            return Err(BackendError::InvalidConfig(
                "sim: the plant needs at least one input and one limit per input".into(),
            ));
        }
        if !(config.counts_per_rev.is_finite() && config.counts_per_rev > 0.0)
            || config.substeps == 0
        {
            return Err(BackendError::InvalidConfig(
                "sim: counts_per_rev must be > 0 and substeps >= 1".into(),
            ));
        }
        let m = plant.input_names().len();
        let maps = vec![EncoderMap::plain(config.counts_per_rev); n / 2];
        let rng = config.noise.map(|nz| SplitMix64::new(nz.seed));
        Ok(Self {
            plant,
            x: x0,
            u: vec![0.0; m],
            delay: vec![0.0; config.input_delay_samples + 1],
            delay_pos: 0,
            scratch: Rk4Scratch::new(n),
            maps,
            rng,
            pacer: None,
            period: 1e-3,
            t: 0.0,
            started: false,
            first: true,
            closed: false,
            last_written: 0.0,
            config,
        })
    }

    /// The true (unquantised) plant state.
    pub fn true_state(&self) -> &[f64] {
        &self.x
    }

    /// The last voltage written by the loop (0 after close).
    pub fn last_written(&self) -> f64 {
        self.last_written
    }

    fn advance(&mut self) {
        // Voltage applied over this interval: the one written `input_delay_samples`
        // samples before the latest write (the oldest slot of the ring).
        let applied = self.delay[self.delay_pos];
        let (lo, hi) = self.plant.input_limits()[0];
        let mut v = applied;
        if let (Some(rng), Some(nz)) = (self.rng.as_mut(), self.config.noise) {
            v += nz.volts_std * rng.next_gaussian();
        }
        self.u[0] = v.clamp(lo, hi);
        let h = self.period / f64::from(self.config.substeps);
        for _ in 0..self.config.substeps {
            self.plant.step(&mut self.x, &self.u, h, &mut self.scratch);
        }
    }
}

impl Backend for SimBackend {
    fn encoders(&self) -> &[EncoderMap] {
        &self.maps
    }

    fn is_virtual_time(&self) -> bool {
        !self.config.real_time
    }

    fn start(&mut self, period_s: f64) -> Result<(), BackendError> {
        if self.closed {
            return Err(BackendError::Closed);
        }
        if !(period_s.is_finite() && period_s > 0.0) {
            return Err(BackendError::InvalidConfig(
                "sim: period must be > 0".into(),
            ));
        }
        self.period = period_s;
        self.pacer = self.config.real_time.then(|| Pacer::new(period_s));
        self.started = true;
        self.first = true;
        Ok(())
    }

    fn wait_next_period(&mut self) -> Result<Tick, BackendError> {
        if !self.started {
            return Err(BackendError::NotStarted);
        }
        let mut missed = 0;
        if let Some(p) = self.pacer.as_mut() {
            let (_, m) = p.wait();
            missed = m;
        }
        if self.first {
            self.first = false;
        } else {
            for _ in 0..=missed {
                self.advance();
                self.t += self.period;
            }
        }
        Ok(Tick { t: self.t, missed })
    }

    fn read_encoders(&mut self, counts: &mut [i32]) -> Result<(), BackendError> {
        if !self.x.iter().all(|v| v.is_finite()) {
            // a diverged simulation is a fault naming it, never counts of 0
            // (which read as a pendulum balanced at rest)
            let names = self.plant.state_names();
            let state = names
                .iter()
                .zip(&self.x)
                .map(|(n, v)| format!("{n} = {v:e}"))
                .collect::<Vec<_>>()
                .join(", ");
            return Err(BackendError::PlantDiverged { t: self.t, state });
        }
        let npos = self.maps.len();
        for (i, c) in counts.iter_mut().enumerate().take(npos) {
            let mut v = self.x[i] / (2.0 * PI) * self.config.counts_per_rev;
            if let (Some(rng), Some(nz)) = (self.rng.as_mut(), self.config.noise) {
                v += nz.counts_std * rng.next_gaussian();
            }
            // finite here; `as` saturates a huge angle instead of wrapping
            *c = v.round() as i32;
        }
        Ok(())
    }

    fn write_voltage(&mut self, volts: f64) -> Result<(), BackendError> {
        if self.closed {
            return Err(BackendError::Closed);
        }
        // Ring buffer of the last `input_delay_samples + 1` writes; the slot
        // after the newest one holds the oldest, which `advance` applies.
        let len = self.delay.len();
        self.delay[self.delay_pos] = volts;
        self.delay_pos = (self.delay_pos + 1) % len;
        self.last_written = volts;
        Ok(())
    }

    fn close(&mut self) -> Result<(), BackendError> {
        self.delay.fill(0.0);
        self.last_written = 0.0;
        self.closed = true;
        self.started = false;
        Ok(())
    }
}

impl Drop for SimBackend {
    fn drop(&mut self) {
        let _ = self.close();
    }
}
