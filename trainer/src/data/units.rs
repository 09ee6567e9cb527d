//! The units a model file and its measurement files state: lengths in µm ("um"), mm, cm, m or inches
//! ("in"), angles in degrees or radians.

use serde::Deserialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    #[serde(alias = "µm")]
    Um,
    Mm,
    Cm,
    M,
    /// The inch, 25.4 mm exactly.
    In,
}

impl LengthUnit {
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Um => 1e-6,
            LengthUnit::Mm => 1e-3,
            LengthUnit::Cm => 1e-2,
            LengthUnit::M => 1.0,
            LengthUnit::In => 0.0254,
        }
    }
    /// The metric units as powers of ten of the metre (exact conversion factors between them).
    fn decimal_exponent(self) -> Option<i32> {
        match self {
            LengthUnit::Um => Some(-6),
            LengthUnit::Mm => Some(-3),
            LengthUnit::Cm => Some(-2),
            LengthUnit::M => Some(0),
            LengthUnit::In => None,
        }
    }
    /// Factor converting a value in `self` into `to`: a correctly rounded power of ten between metric
    /// units (1000, 1e-3, … exactly as written), else the ratio of their lengths in metres.
    pub fn factor_to(self, to: LengthUnit) -> f64 {
        match (self.decimal_exponent(), to.decimal_exponent()) {
            _ if self == to => 1.0,
            (Some(a), Some(b)) if a >= b => 10f64.powi(a - b),
            (Some(a), Some(b)) => 1.0 / 10f64.powi(b - a),
            _ => self.metres() / to.metres(),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Um => "um",
            LengthUnit::Mm => "mm",
            LengthUnit::Cm => "cm",
            LengthUnit::M => "m",
            LengthUnit::In => "in",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AngleUnit {
    Deg,
    Rad,
}

impl AngleUnit {
    /// Radians per unit.
    pub fn radians(self) -> f64 {
        match self {
            AngleUnit::Deg => std::f64::consts::PI / 180.0,
            AngleUnit::Rad => 1.0,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            AngleUnit::Deg => "deg",
            AngleUnit::Rad => "rad",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 26: only m and mm were known ("cm" was a bare TOML error).
    #[test]
    fn length_units_convert_exactly_between_metric_units() {
        assert_eq!(LengthUnit::M.factor_to(LengthUnit::Mm), 1000.0);
        assert_eq!(LengthUnit::Mm.factor_to(LengthUnit::M), 1e-3);
        assert_eq!(LengthUnit::Cm.factor_to(LengthUnit::Mm), 10.0);
        assert_eq!(LengthUnit::Um.factor_to(LengthUnit::Mm), 1e-3);
        assert_eq!(LengthUnit::M.factor_to(LengthUnit::Um), 1e6);
        assert_eq!(LengthUnit::In.factor_to(LengthUnit::Mm), 25.4);
        assert!((LengthUnit::Mm.factor_to(LengthUnit::In) * 25.4 - 1.0).abs() < 1e-15);
        #[derive(Deserialize)]
        struct U {
            u: LengthUnit,
        }
        for (text, unit) in [("um", LengthUnit::Um), ("µm", LengthUnit::Um), ("cm", LengthUnit::Cm), ("in", LengthUnit::In)] {
            assert_eq!(toml::from_str::<U>(&format!("u = \"{text}\"")).unwrap().u, unit);
        }
    }
}
