//! A profile CSV: a header naming x and z with their units (`x_mm,z_um`; also `x_um`, and z
//! in `nm`, `um` or `mm`), then one point per line, x equally spaced. Read into the pitch and
//! the heights in µm of one line.
//!
//! Pure (no I/O), inside the reading layer: text in, values out; depends on [`super::text`].

use super::text::{column_name, units_named, Layout, Unit};

/// A profile as read: its pitch, heights (in the file's z unit) and the units its header names.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileText {
    /// x pitch, mm.
    pub pitch_x_mm: f64,
    /// x of the first point, mm.
    pub x0_mm: f64,
    /// Heights, in `z_unit` (µm when the header names none).
    pub z: Vec<f64>,
    /// The z unit the header names, if any.
    pub z_unit: Option<Unit>,
    /// The x unit the header names.
    pub x_unit: Unit,
}

/// The header a profile CSV needs, for the messages.
const NEEDS: &str = "a profile CSV's header names x and z with their units, x_mm,z_um (x in mm or um, z in nm, um or mm), two columns";

/// Whether `layout`'s header starts with an x column: the file is a profile, not a grid.
pub fn is_profile(layout: &Layout) -> bool {
    layout.header.as_ref().is_some_and(|(_, h)| {
        layout
            .dialect
            .fields(h)
            .first()
            .is_some_and(|f| column_name(f) == "x")
    })
}

/// Reads the profile in `text` (laid out as `layout` says, its header naming x first).
pub fn read_profile(text: &str, layout: &Layout) -> Result<ProfileText, String> {
    let d = &layout.dialect;
    let (_, header) = layout.header.as_ref().ok_or_else(|| NEEDS.to_string())?;
    let columns = d.fields(header);
    let names: Vec<String> = columns.iter().map(|c| column_name(c)).collect();
    if names != ["x", "z"] {
        return Err(format!(
            "{NEEDS}; this one is {:?}: keep only those two columns",
            header.trim()
        ));
    }
    let x_unit = match units_named(columns[0]).as_slice() {
        [Unit::Mm] => Unit::Mm,
        [Unit::Um] => Unit::Um,
        _ => {
            return Err(format!(
                "{NEEDS}; the x column {:?} names no unit of mm or um",
                columns[0]
            ))
        }
    };
    let z_unit = match units_named(columns[1]).as_slice() {
        [] => None,
        [u] => Some(*u),
        _ => {
            return Err(format!(
                "{NEEDS}; the z column {:?} names more than one unit",
                columns[1]
            ))
        }
    };
    let mut x = Vec::new();
    let mut z = Vec::new();
    for (n, line) in text.lines().enumerate().skip(layout.data_from) {
        if line.trim().is_empty() {
            continue;
        }
        let f = d.fields(line);
        match f.as_slice() {
            [xf, zf] => {
                if let (Some(xv), Some(zv)) = (d.number(xf), d.number(zf)) {
                    x.push(xv);
                    z.push(zv);
                    continue;
                }
            }
            [_, _, _, _] if d.separator == b',' && !d.decimal_comma => {
                return Err(format!(
                    "line {} holds 4 values where the header names 2: {line:?}; decimal commas with ',' between the values cannot be read without guessing: write the file with ';' between values, or with decimal points",
                    n + 1
                ))
            }
            _ => {}
        }
        return Err(format!("line {} is not two numbers x,z: {line:?}", n + 1));
    }
    let x_mm = x_unit.in_um() / 1000.0;
    let (first, last) = match (x.first(), x.last()) {
        (Some(f), Some(l)) if x.len() >= 2 => (*f, *l),
        _ => return Err("fewer than 2 points".to_string()),
    };
    let pitch = (last - first) / (x.len() - 1) as f64;
    if let Some(i) = x
        .windows(2)
        .position(|w| matches!(w, [a, b] if ((b - a) - pitch).abs() > 0.01 * pitch.abs()))
    {
        return Err(format!(
            "x is not uniformly spaced at row {} (pitch {} mm); resample the profile first",
            i + 2,
            pitch * x_mm
        ));
    }
    if let Some(i) = z.iter().position(|v| !v.is_finite()) {
        let count = z.iter().filter(|v| !v.is_finite()).count();
        return Err(format!(
            "{count} of its {} heights are not finite (NaN or infinite: not measured), the first at row {}; nothing is filled in: fill or crop them in the software that wrote the file",
            z.len(),
            i + 2
        ));
    }
    Ok(ProfileText {
        pitch_x_mm: if x_unit == Unit::Mm {
            pitch
        } else {
            pitch * x_mm
        },
        x0_mm: first * x_mm,
        z,
        z_unit,
        x_unit,
    })
}

#[cfg(test)]
mod tests {
    use super::super::text::layout;
    use super::*;

    fn read(text: &str) -> Result<ProfileText, String> {
        let l = layout(text)?;
        assert!(is_profile(&l), "{text:?}");
        read_profile(text, &l)
    }

    #[test]
    fn a_plain_profile_keeps_its_numbers() {
        let p = read("x_mm,z_um\n0,1.5\n0.0015,-2\n0.003,3\n").unwrap();
        assert_eq!((p.pitch_x_mm, p.z.clone()), (0.0015, vec![1.5, -2.0, 3.0]));
        assert_eq!((p.x_unit, p.z_unit), (Unit::Mm, Some(Unit::Um)));
    }

    #[test]
    fn other_units_separators_and_decimal_commas_are_read() {
        let p = read("x [um];z [nm]\n1,5;1,5\n3;2\n4,5;3\n").unwrap();
        assert!((p.pitch_x_mm - 0.0015).abs() < 1e-15, "{}", p.pitch_x_mm);
        assert!((p.x0_mm - 0.0015).abs() < 1e-15, "{}", p.x0_mm);
        assert_eq!(
            (p.z.clone(), p.z_unit),
            (vec![1.5, 2.0, 3.0], Some(Unit::Nm))
        );
        let p = read("x_mm,z\n0,1\n1,2\n").unwrap();
        assert_eq!(p.z_unit, None);
    }

    #[test]
    fn what_cannot_be_read_is_named() {
        let e = read("x_mm,z_um,w\n0,1,2\n").unwrap_err();
        assert!(e.contains("keep only those two columns"), "{e}");
        let e = read("x,z_um\n0,1\n1,2\n").unwrap_err();
        assert!(e.contains("names no unit"), "{e}");
        let e = read("x_mm,z_um\n0,1\n1,x\n").unwrap_err();
        assert!(e.contains("line 3 is not two numbers"), "{e}");
        let e = read("x_mm,z_um\n0,0015,5,839\n").unwrap_err();
        assert!(e.contains("decimal commas with ','"), "{e}");
        let e = read("x_mm,z_um\n0,1\n1,NaN\n2,3\n").unwrap_err();
        assert!(
            e.starts_with("1 of its 3 heights are not finite") && e.contains("row 3"),
            "{e}"
        );
        let e = read("x_mm,z_um\n0,1\n1,2\n3,3\n").unwrap_err();
        assert!(e.contains("x is not uniformly spaced at row 2"), "{e}");
    }
}
