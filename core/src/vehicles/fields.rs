//! The field table of a model's parameters: each field's name in a vehicle file, its unit and
//! its plausible range, and reading, setting and range-checking fields by name. One place for
//! it; a model gives only its table and the name-to-field mapping ([`FieldTable`]).

/// One field of a model's parameters in a vehicle file: name, unit, plausible range (both ends
/// included: wide enough for any vehicle of the model, narrow enough to reject a typo by orders
/// of magnitude).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelField {
    /// Field name (in the model's section of a vehicle file).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// Plausible range (lo, hi).
    pub range: (f64, f64),
}

impl ModelField {
    /// A field (for the models' `const` tables).
    pub const fn new(name: &'static str, unit: &'static str, lo: f64, hi: f64) -> Self {
        Self {
            name,
            unit,
            range: (lo, hi),
        }
    }

    /// `value` if it lies inside the range (NaN does not).
    pub fn check(&self, value: f64) -> Result<f64, FieldError> {
        let (lo, hi) = self.range;
        if (lo..=hi).contains(&value) {
            Ok(value)
        } else {
            Err(FieldError::OutOfRange {
                name: self.name,
                value,
                lo,
                hi,
                unit: self.unit,
            })
        }
    }
}

/// Why a field cannot be read or set.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum FieldError {
    /// No field of that name.
    #[error("no field of that name")]
    Unknown,
    /// A value outside its field's plausible range (or not finite).
    #[error("field `{name}` = {value} {unit} is outside {lo} ..= {hi} {unit}")]
    OutOfRange {
        /// The field.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Lower end of the range.
        lo: f64,
        /// Upper end of the range.
        hi: f64,
        /// The field's unit.
        unit: &'static str,
    },
}

/// A model's parameters as named fields.
pub trait FieldTable: Copy {
    /// Every field, in the order of the model's documentation.
    const FIELDS: &'static [ModelField];

    /// The parameter behind the field `name`.
    fn field_mut(&mut self, name: &str) -> Option<&mut f64>;

    /// The value of the field `name`.
    fn get(&self, name: &str) -> Option<f64> {
        let mut copy = *self;
        copy.field_mut(name).map(|v| *v)
    }

    /// Sets the field `name` to `value` if it is inside the field's range.
    fn set(&mut self, name: &str, value: f64) -> Result<(), FieldError> {
        let field = Self::FIELDS
            .iter()
            .find(|f| f.name == name)
            .ok_or(FieldError::Unknown)?;
        *self.field_mut(name).ok_or(FieldError::Unknown)? = field.check(value)?;
        Ok(())
    }

    /// Every field inside its range; the first offender.
    fn check_ranges(&self) -> Result<(), FieldError> {
        for f in Self::FIELDS {
            f.check(self.get(f.name).ok_or(FieldError::Unknown)?)?;
        }
        Ok(())
    }
}

/// The checks every model's field table passes (each model's `tests.rs` calls it on a named
/// set): every field reads back what was set and changes the parameters, and a value out of
/// range, NaN or an unknown name is rejected naming the field.
#[cfg(test)]
pub(crate) fn assert_table_covers_every_field<T: FieldTable + PartialEq + core::fmt::Debug>(t: T) {
    t.check_ranges().unwrap();
    for f in T::FIELDS {
        let v = t.get(f.name).unwrap();
        let mid = 0.5 * (f.range.0 + f.range.1);
        let mut u = t;
        u.set(f.name, mid).unwrap();
        assert_eq!(u.get(f.name), Some(mid), "{}", f.name);
        assert!(u != t || v == mid, "{} sets nothing", f.name);
        let below = f.range.0 - 1.0 - f.range.0.abs();
        let e = u.set(f.name, below).unwrap_err();
        assert!(
            matches!(e, FieldError::OutOfRange { name, .. } if name == f.name),
            "{e}"
        );
        assert!(u.set(f.name, f64::NAN).is_err(), "{} takes NaN", f.name);
        assert_eq!(
            u.get(f.name),
            Some(mid),
            "{} changed by a refused set",
            f.name
        );
    }
    let mut u = t;
    assert_eq!(u.set("no_such", 1.0), Err(FieldError::Unknown));
    assert_eq!(u, t);
}
