//! Range checks that name the JSON path of the value they reject.
//!
//! Every message has the form `"{rule with unit}, got {value}"`, e.g. `"must be > 0 m, got
//! -0.01"`; the caller's [`SceneError::Invalid`] puts the JSON path in front. Checks are chained:
//! `num("object.thickness", d, "m")?.gt(0.0)?.le(10.0)?;` where [`num`] itself rejects
//! non-finite values (`"must be finite, got inf"`).

use super::SceneError;

/// Result of one check.
pub(crate) type Check = Result<(), SceneError>;

/// Formats a number for an error message: plain decimals for magnitudes in [1e-4, 1e6),
/// scientific notation otherwise (so `1e300` does not print three hundred zeros), and `inf`,
/// `-inf`, `NaN` as Rust prints them.
pub(crate) fn fmt_num(value: f64) -> String {
    let magnitude = value.abs();
    if value == 0.0 || !value.is_finite() || (1e-4..1e6).contains(&magnitude) {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// `"0.002 m"`, or just `"0.002"` for a dimensionless quantity.
pub(crate) fn with_unit(value: f64, unit: &str) -> String {
    if unit.is_empty() {
        fmt_num(value)
    } else {
        format!("{} {unit}", fmt_num(value))
    }
}

/// A finite number at a JSON path, ready for range checks.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Num<'a> {
    path: &'a str,
    value: f64,
    unit: &'a str,
}

/// Starts the checks of `value` at `path` (unit `unit`, `""` if dimensionless).
///
/// # Errors
/// `"{path}: must be finite, got inf"` for infinities and NaN.
pub(crate) fn num<'a>(path: &'a str, value: f64, unit: &'a str) -> Result<Num<'a>, SceneError> {
    if value.is_finite() {
        Ok(Num { path, value, unit })
    } else {
        Err(SceneError::invalid(path, format!("must be finite, got {}", fmt_num(value))))
    }
}

impl<'a> Num<'a> {
    fn fail(&self, rule: String) -> SceneError {
        SceneError::invalid(self.path, format!("must be {rule}, got {}", fmt_num(self.value)))
    }

    fn compare(self, ok: bool, op: &str, bound: f64) -> Result<Self, SceneError> {
        if ok {
            Ok(self)
        } else {
            Err(self.fail(format!("{op} {}", with_unit(bound, self.unit))))
        }
    }

    /// value > bound.
    pub(crate) fn gt(self, bound: f64) -> Result<Self, SceneError> {
        self.compare(self.value > bound, ">", bound)
    }

    /// value >= bound.
    pub(crate) fn ge(self, bound: f64) -> Result<Self, SceneError> {
        self.compare(self.value >= bound, ">=", bound)
    }

    /// value < bound.
    pub(crate) fn lt(self, bound: f64) -> Result<Self, SceneError> {
        self.compare(self.value < bound, "<", bound)
    }

    /// value <= bound.
    pub(crate) fn le(self, bound: f64) -> Result<Self, SceneError> {
        self.compare(self.value <= bound, "<=", bound)
    }

    /// value in an interval; `closed_lo` / `closed_hi` say whether each end is included.
    /// Message: `"must be in [0, 1], got 1.5"`, `"must be in (0, 180) deg, got 200"`.
    pub(crate) fn within(self, lo: f64, closed_lo: bool, hi: f64, closed_hi: bool) -> Result<Self, SceneError> {
        let above = if closed_lo { self.value >= lo } else { self.value > lo };
        let below = if closed_hi { self.value <= hi } else { self.value < hi };
        if above && below {
            return Ok(self);
        }
        let unit = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        Err(self.fail(format!(
            "in {}{}, {}{}{unit}",
            if closed_lo { '[' } else { '(' },
            fmt_num(lo),
            fmt_num(hi),
            if closed_hi { ']' } else { ')' },
        )))
    }

    /// value > `other`, where `other` is the value at JSON path `other_path`.
    /// Message: `"must be > lamps[0].on (5 s), got 3"`.
    pub(crate) fn gt_other(self, other_path: &str, other: f64) -> Result<Self, SceneError> {
        self.compare_other(self.value > other, ">", other_path, other)
    }

    /// value >= `other` (see [`Num::gt_other`]).
    pub(crate) fn ge_other(self, other_path: &str, other: f64) -> Result<Self, SceneError> {
        self.compare_other(self.value >= other, ">=", other_path, other)
    }

    /// value <= `other` (see [`Num::gt_other`]).
    pub(crate) fn le_other(self, other_path: &str, other: f64) -> Result<Self, SceneError> {
        self.compare_other(self.value <= other, "<=", other_path, other)
    }

    fn compare_other(self, ok: bool, op: &str, other_path: &str, other: f64) -> Result<Self, SceneError> {
        if ok {
            Ok(self)
        } else {
            Err(self.fail(format!("{op} {other_path} ({})", with_unit(other, self.unit))))
        }
    }
}

/// Checks every component of a 3-vector is finite; paths `"{path}[0]"` to `"{path}[2]"`.
pub(crate) fn finite3(path: &str, v: [f64; 3]) -> Check {
    for (i, &x) in v.iter().enumerate() {
        num(&format!("{path}[{i}]"), x, "m")?;
    }
    Ok(())
}

/// Integer range check `lo <= value <= hi`: `"must be >= 1 pixels, got 0"`.
pub(crate) fn int_in(path: &str, value: u64, lo: u64, hi: u64, unit: &str) -> Check {
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    if value < lo {
        Err(SceneError::invalid(path, format!("must be >= {lo}{unit}, got {value}")))
    } else if value > hi {
        Err(SceneError::invalid(path, format!("must be <= {hi}{unit}, got {value}")))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(r: Result<Num<'_>, SceneError>) -> String {
        r.expect_err("check should fail").to_string()
    }

    #[test]
    fn messages_have_path_rule_unit_and_value() {
        assert_eq!(
            msg(num("object.thickness", -0.01, "m").and_then(|n| n.gt(0.0))),
            "object.thickness: must be > 0 m, got -0.01"
        );
        assert_eq!(msg(num("x", f64::INFINITY, "m")), "x: must be finite, got inf");
        assert_eq!(msg(num("x", f64::NAN, "K")), "x: must be finite, got NaN");
        assert_eq!(
            msg(num("material.emissivity", 1.5, "").and_then(|n| n.within(0.0, true, 1.0, true))),
            "material.emissivity: must be in [0, 1], got 1.5"
        );
        assert_eq!(
            msg(num("camera.hfov_deg", 180.0, "deg").and_then(|n| n.within(0.0, false, 180.0, false))),
            "camera.hfov_deg: must be in (0, 180) deg, got 180"
        );
        assert_eq!(
            msg(num("lamps[0].off", 1.0, "s").and_then(|n| n.gt_other("lamps[0].on", 2.0))),
            "lamps[0].off: must be > lamps[0].on (2 s), got 1"
        );
    }

    #[test]
    fn passing_checks_chain() {
        assert!(num("a", 0.5, "m")
            .and_then(|n| n.gt(0.0))
            .and_then(|n| n.le(1.0))
            .and_then(|n| n.within(0.0, true, 1.0, false))
            .is_ok());
    }

    #[test]
    fn extreme_numbers_print_compactly() {
        assert_eq!(fmt_num(1e300), "1e300");
        assert_eq!(fmt_num(-2.5e-9), "-2.5e-9");
        assert_eq!(fmt_num(0.0), "0");
        assert_eq!(fmt_num(1.0 / 60.0), "0.016666666666666666");
        assert_eq!(fmt_num(f64::NEG_INFINITY), "-inf");
    }

    #[test]
    fn integer_bounds() {
        assert!(int_in("camera.width", 640, 1, 16384, "pixels").is_ok());
        assert_eq!(
            int_in("camera.width", 0, 1, 16384, "pixels").unwrap_err().to_string(),
            "camera.width: must be >= 1 pixels, got 0"
        );
        assert_eq!(
            int_in("camera.height", 20000, 1, 16384, "pixels").unwrap_err().to_string(),
            "camera.height: must be <= 16384 pixels, got 20000"
        );
    }
}
