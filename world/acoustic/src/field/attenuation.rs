//! How loud a source is at a sensor: spherical spreading (amplitude ∝ 1/d,
//! Kinsler et al., the paper's reference [15]) times atmospheric
//! absorption (ISO 9613-1 / Bass et al. 1995, the paper's reference [16]).

/// Amplitude gain from a source to a sensor at distance d:
/// `(d₀ / max(d, d₀)) · 10^(−α d / 20)`, and 0 beyond the sensing range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attenuation {
    /// Distance at which the source's own level is given (1 m).
    pub reference_distance: f64,
    /// Atmospheric absorption, dB per metre.
    pub absorption_db_per_m: f64,
}

impl Default for Attenuation {
    /// 2 kHz (the middle of bird song) at 20 °C, 50 % humidity, sea level:
    /// about 9.9 dB/km.
    fn default() -> Self {
        Attenuation {
            reference_distance: 1.0,
            absorption_db_per_m: iso9613_absorption(2000.0, 20.0, 50.0, 101.325),
        }
    }
}

impl Attenuation {
    /// The amplitude gain at distance `d` metres.
    #[inline]
    pub(crate) fn gain(&self, d: f64) -> f64 {
        let spreading = self.reference_distance / d.max(self.reference_distance);
        spreading * 10f64.powf(-self.absorption_db_per_m * d / 20.0)
    }

    pub fn validate(&self) -> Result<(), String> {
        if !(self.reference_distance.is_finite() && self.reference_distance > 0.0) {
            return Err(format!(
                "attenuation reference distance must be > 0, got {}",
                self.reference_distance
            ));
        }
        if !(self.absorption_db_per_m.is_finite() && self.absorption_db_per_m >= 0.0) {
            return Err(format!(
                "atmospheric absorption must be ≥ 0 dB/m, got {}",
                self.absorption_db_per_m
            ));
        }
        Ok(())
    }
}

/// Pure-tone atmospheric absorption coefficient, dB/m (ISO 9613-1:1993,
/// equations 3–5): frequency in Hz, temperature in °C, relative humidity
/// in %, pressure in kPa.
pub(crate) fn iso9613_absorption(frequency: f64, celsius: f64, humidity: f64, kpa: f64) -> f64 {
    let t = celsius + 273.15;
    let t0 = 293.15;
    let t01 = 273.16;
    let pr = 101.325;
    let pa = kpa / pr;
    let c = -6.8346 * (t01 / t).powf(1.261) + 4.6151;
    let h = humidity * 10f64.powf(c) / pa;
    let fr_o = pa * (24.0 + 4.04e4 * h * (0.02 + h) / (0.391 + h));
    let fr_n = pa
        * (t / t0).powf(-0.5)
        * (9.0 + 280.0 * h * (-4.170 * ((t / t0).powf(-1.0 / 3.0) - 1.0)).exp());
    let f2 = frequency * frequency;
    8.686
        * f2
        * (1.84e-11 / pa * (t / t0).sqrt()
            + (t / t0).powf(-2.5)
                * (0.01275 * (-2239.1 / t).exp() / (fr_o + f2 / fr_o)
                    + 0.1068 * (-3352.0 / t).exp() / (fr_n + f2 / fr_n)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso9613_matches_its_table() {
        // ISO 9613-2 Table 2 (computed from 9613-1), dB/km.
        for (celsius, humidity, f, table) in [
            (10.0, 70.0, 1000.0, 3.7),
            (10.0, 70.0, 2000.0, 9.7),
            (10.0, 70.0, 4000.0, 32.8),
            (10.0, 70.0, 8000.0, 117.0),
            (20.0, 70.0, 1000.0, 5.0),
            (20.0, 70.0, 2000.0, 9.0),
            (20.0, 70.0, 4000.0, 22.9),
            (20.0, 70.0, 8000.0, 76.6),
        ] {
            let a = iso9613_absorption(f, celsius, humidity, 101.325) * 1000.0;
            assert!(
                (a / table - 1.0).abs() < 0.02,
                "{celsius} °C {humidity} % {f} Hz: {a} dB/km vs {table}"
            );
        }
    }

    #[test]
    fn gain_falls_with_distance() {
        let a = Attenuation::default();
        assert!((a.gain(0.1) - 1.0).abs() < 1e-3);
        // Inside the reference distance only absorption acts.
        assert!(a.gain(0.5) > a.gain(1.0) && a.gain(0.5) < 1.0);
        let g = a.gain(250.0);
        assert!((0.002..0.004).contains(&g), "{g}");
        assert!(a.gain(100.0) > a.gain(101.0));
    }
}
