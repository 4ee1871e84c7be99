//! A reader of MATLAB v5 `.mat` files (level 5 MAT-file format, what MATLAB
//! writes with `-v6`/`-v7` and `scipy.io.savemat` writes), for [`crate::data`].
//!
//! It reads every top-level variable: real numeric arrays of any class (double,
//! single, int8 … uint64, logical) whatever type their data are stored in (MATLAB
//! stores a double array of small whole numbers as `miUINT8`, for instance), as
//! `f64`; compressed variables (`miCOMPRESSED`, zlib) are inflated. Cells, structs,
//! objects, sparse and character arrays are listed as skipped, never misread.
//!
//! The file is read completely or not at all: a file cut off inside a variable, or
//! a damaged compressed variable, is an error naming the variable where it stops
//! (never a dataset with the last variables silently missing).

/// One variable of a `.mat` file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Variable {
    /// Its name.
    pub name: String,
    /// Its dimensions.
    pub dims: Vec<usize>,
    /// Its values (column-major), or why it is not a real numeric array.
    pub values: Result<Vec<f64>, String>,
    /// Whether it is of a class that is never data (cell, struct, object,
    /// character, sparse): such variables are skipped, not errors.
    pub non_numeric: bool,
}

// Data types (MAT-file format, Table 1-1).
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// Array classes 6 (double) … 15 (uint64) are numeric.
const NUMERIC_CLASSES: std::ops::RangeInclusive<u32> = 6..=15;

/// The bytes of one file with its byte order.
#[derive(Clone, Copy)]
struct Bytes<'a> {
    b: &'a [u8],
    big_endian: bool,
}

impl Bytes<'_> {
    fn u32_at(&self, at: usize) -> Option<u32> {
        let s: [u8; 4] = self.b.get(at..at + 4)?.try_into().ok()?;
        Some(if self.big_endian {
            u32::from_be_bytes(s)
        } else {
            u32::from_le_bytes(s)
        })
    }
    /// The element whose tag is at `at`: its type, its data and where the next
    /// element starts (data padded to 8 bytes, except a compressed element's).
    /// [`Cut`] when the element runs past the end of the bytes.
    fn tag(&self, at: usize) -> Result<Tag, Cut> {
        let first = self.u32_at(at).ok_or(Cut {
            declared: 8,
            remaining: self.b.len().saturating_sub(at),
        })?;
        if first >> 16 != 0 {
            // Small data element: type and length packed in 4 bytes, data in 4.
            let len = (first >> 16) as usize;
            if len > 4 || self.b.len() < at + 8 {
                return Err(Cut {
                    declared: 8,
                    remaining: self.b.len() - at,
                });
            }
            return Ok(Tag {
                ty: first & 0xffff,
                data: at + 4..at + 4 + len,
                next: at + 8,
            });
        }
        let len = self.u32_at(at + 4).ok_or(Cut {
            declared: 8,
            remaining: self.b.len().saturating_sub(at),
        })? as usize;
        let end = at + 8 + len;
        if end > self.b.len() {
            return Err(Cut {
                declared: len,
                remaining: self.b.len() - at - 8,
            });
        }
        let next = if first == MI_COMPRESSED {
            end
        } else {
            end.next_multiple_of(8)
        };
        Ok(Tag {
            ty: first,
            data: at + 8..end,
            next,
        })
    }
}

struct Tag {
    ty: u32,
    data: std::ops::Range<usize>,
    next: usize,
}

/// An element that runs past the end of the bytes it is in.
#[derive(Debug)]
struct Cut {
    declared: usize,
    remaining: usize,
}

/// Read every variable of the file `bytes` (header included). Errors say what is
/// wrong and, for a cut-off or damaged file, at which variable; `max_bytes` bounds
/// what compressed variables may inflate to.
pub(crate) fn read(bytes: &[u8], max_bytes: usize) -> Result<Vec<Variable>, String> {
    if bytes.len() < 128 {
        return Err(format!(
            "is cut off: {} bytes, shorter than the 128-byte MAT-file header",
            bytes.len()
        ));
    }
    let big_endian = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        other => {
            return Err(format!(
                "has no MAT-file byte-order mark (bytes 126–127 are {other:?}, not `IM` or `MI`)"
            ));
        }
    };
    let file = Bytes {
        b: bytes,
        big_endian,
    };
    let mut out: Vec<Variable> = Vec::new();
    let mut inflated_total = 0usize;
    let mut at = 128;
    while at < bytes.len() {
        let index = out.len() + 1;
        let after = || match out.last() {
            Some(v) => format!("after `{}`", v.name),
            None => "first".to_string(),
        };
        let tag = match file.tag(at) {
            Ok(t) => t,
            Err(c) => {
                // What can be read of the cut variable names it.
                let partial = &bytes[(at + 8).min(bytes.len())..];
                let name = match file.u32_at(at) {
                    Some(MI_COMPRESSED) => {
                        inflate_prefix(partial, 4096).and_then(|d| matrix_name(&d, big_endian))
                    }
                    Some(MI_MATRIX) => matrix_body_name(partial, big_endian),
                    _ => None,
                };
                let which = match name {
                    Some(n) => format!("variable `{n}` (the {}, {})", ordinal(index), after()),
                    None => format!("the {} variable ({})", ordinal(index), after()),
                };
                return Err(format!(
                    "is cut off (truncated) inside {which}: it declares {} bytes but only {} remain; a .mat file is read whole or not at all",
                    c.declared, c.remaining
                ));
            }
        };
        let body = &bytes[tag.data.clone()];
        let label = |what: &str| format!("the {} variable ({}): {what}", ordinal(index), after());
        let var = match tag.ty {
            MI_MATRIX => matrix(body, big_endian).map_err(|e| label(&e))?,
            MI_COMPRESSED => {
                let data =
                    inflate(body, max_bytes.saturating_sub(inflated_total)).map_err(|e| {
                        let name =
                            inflate_prefix(body, 4096).and_then(|d| matrix_name(&d, big_endian));
                        match name {
                            Some(n) => format!(
                                "variable `{n}` (the {}, {}) cannot be decompressed: {e}",
                                ordinal(index),
                                after()
                            ),
                            None => label(&format!("cannot be decompressed: {e}")),
                        }
                    })?;
                inflated_total += data.len();
                let inner = Bytes {
                    b: &data,
                    big_endian,
                };
                let t = inner.tag(0).map_err(|c| {
                    label(&format!(
                        "its compressed data declare {} bytes but inflate to {}; the file is damaged",
                        c.declared, c.remaining
                    ))
                })?;
                if t.ty != MI_MATRIX {
                    Variable::skipped(format!("compressed element of type {}", t.ty))
                } else {
                    matrix(&data[t.data], big_endian).map_err(|e| label(&e))?
                }
            }
            other => Variable::skipped(format!("top-level element of type {other}")),
        };
        if !var.name.is_empty() || var.values.is_ok() {
            out.push(var);
        }
        at = tag.next;
    }
    Ok(out)
}

impl Variable {
    fn skipped(why: String) -> Self {
        Self {
            name: String::new(),
            dims: Vec::new(),
            values: Err(why),
            non_numeric: true,
        }
    }
}

fn ordinal(i: usize) -> String {
    let suffix = match (i % 10, i % 100) {
        (1, n) if n != 11 => "st",
        (2, n) if n != 12 => "nd",
        (3, n) if n != 13 => "rd",
        _ => "th",
    };
    format!("{i}{suffix}")
}

/// The name in the bytes of an `miMATRIX` element (tag included), if they reach it.
fn matrix_name(element: &[u8], big_endian: bool) -> Option<String> {
    matrix_body_name(element.get(8..)?, big_endian)
}

/// The name in the body of an `miMATRIX` element, if the bytes reach it.
fn matrix_body_name(body: &[u8], big_endian: bool) -> Option<String> {
    let b = Bytes {
        b: body,
        big_endian,
    };
    let flags = b.tag(0).ok()?;
    let dims = b.tag(flags.next).ok()?;
    let name = b.tag(dims.next).ok()?;
    let n = String::from_utf8_lossy(&body[name.data]).into_owned();
    (!n.is_empty()).then_some(n)
}

/// One `miMATRIX` body: flags, dimensions, name, real and imaginary parts.
fn matrix(body: &[u8], big_endian: bool) -> Result<Variable, String> {
    let b = Bytes {
        b: body,
        big_endian,
    };
    let cut = |what: &str, c: Cut| {
        format!(
            "its {what} declares {} bytes but only {} are in the variable; the file is damaged",
            c.declared, c.remaining
        )
    };
    let flags = b.tag(0).map_err(|c| cut("array-flags element", c))?;
    let word = b.u32_at(flags.data.start).unwrap_or(0);
    let class = word & 0xff;
    let complex = word & 0x0800 != 0;
    let dims_tag = b
        .tag(flags.next)
        .map_err(|c| cut("dimensions element", c))?;
    let dims: Vec<usize> = dims_tag
        .data
        .clone()
        .step_by(4)
        .filter_map(|i| b.u32_at(i))
        .map(|d| d as usize)
        .collect();
    let name_tag = b.tag(dims_tag.next).map_err(|c| cut("name element", c))?;
    let name = String::from_utf8_lossy(&body[name_tag.data]).into_owned();
    let mut var = Variable {
        name,
        dims,
        values: Err(String::new()),
        non_numeric: false,
    };
    if !NUMERIC_CLASSES.contains(&class) {
        let kind = match class {
            1 => "a cell array",
            2 => "a struct",
            3 => "an object",
            4 => "a character array",
            5 => "a sparse array",
            _ => "not a numeric array",
        };
        var.values = Err(format!(
            "variable is {kind}; only real numeric vectors are data"
        ));
        var.non_numeric = true;
        return Ok(var);
    }
    let count = var
        .dims
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| format!("variable `{}` has dimensions too large", var.name))?;
    let real = b
        .tag(name_tag.next)
        .map_err(|c| cut(&format!("real part of `{}`", var.name), c))?;
    if complex {
        var.values = Err("variable is complex; only real signals are data".into());
        return Ok(var);
    }
    let values = match numbers(real.ty, &body[real.data], big_endian) {
        Ok(v) => v,
        Err(e) => {
            var.values = Err(e);
            return Ok(var);
        }
    };
    if values.len() != count {
        return Err(format!(
            "variable `{}` holds {} values where its dimensions {:?} say {count}; the file is damaged",
            var.name,
            values.len(),
            var.dims
        ));
    }
    var.values = Ok(values);
    Ok(var)
}

/// The numbers stored in `data` as type `ty`, as `f64` (64-bit integers only when
/// exact).
fn numbers(ty: u32, data: &[u8], big_endian: bool) -> Result<Vec<f64>, String> {
    fn each<const N: usize>(
        data: &[u8],
        f: impl Fn([u8; N]) -> Result<f64, String>,
    ) -> Result<Vec<f64>, String> {
        if !data.len().is_multiple_of(N) {
            return Err(format!(
                "{} bytes of data are not a whole number of {N}-byte values; the file is damaged",
                data.len()
            ));
        }
        data.chunks_exact(N)
            .map(|c| f(c.try_into().expect("chunks of N")))
            .collect()
    }
    macro_rules! num {
        ($t:ty) => {
            each(data, |c| {
                Ok(if big_endian {
                    <$t>::from_be_bytes(c)
                } else {
                    <$t>::from_le_bytes(c)
                } as f64)
            })
        };
    }
    macro_rules! exact64 {
        ($t:ty) => {
            each(data, |c| {
                let i = if big_endian {
                    <$t>::from_be_bytes(c)
                } else {
                    <$t>::from_le_bytes(c)
                };
                let f = i as f64;
                // `as` saturates: f as $t == i only when f is exactly i.
                if f as $t == i && f != <$t>::MAX as f64 {
                    Ok(f)
                } else {
                    Err(format!(
                        "64-bit integer {i} has no exact f64 value; convert the variable to double"
                    ))
                }
            })
        };
    }
    match ty {
        MI_INT8 => num!(i8),
        MI_UINT8 => num!(u8),
        MI_INT16 => num!(i16),
        MI_UINT16 => num!(u16),
        MI_INT32 => num!(i32),
        MI_UINT32 => num!(u32),
        MI_SINGLE => num!(f32),
        MI_DOUBLE => num!(f64),
        MI_INT64 => exact64!(i64),
        MI_UINT64 => exact64!(u64),
        other => Err(format!(
            "values stored as data type {other}, which is not numeric"
        )),
    }
}

/// Inflate a zlib stream completely, to at most `max_bytes`.
fn inflate(data: &[u8], max_bytes: usize) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let dec = libflate::zlib::Decoder::new(data).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    dec.take(max_bytes as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| e.to_string())?;
    if out.len() > max_bytes {
        return Err(format!(
            "it inflates to more than {max_bytes} bytes, more than a data file may hold"
        ));
    }
    Ok(out)
}

/// The first up to `n` bytes a (possibly cut) zlib stream inflates to.
fn inflate_prefix(data: &[u8], n: usize) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut dec = libflate::zlib::Decoder::new(data).ok()?;
    let mut out = vec![0u8; n];
    let mut got = 0;
    while got < n {
        match dec.read(&mut out[got..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => got += k,
        }
    }
    out.truncate(got);
    Some(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A MAT v5 element (tag + data, padded to 8) of type `ty`.
    fn element(ty: u32, data: &[u8]) -> Vec<u8> {
        let mut v = Vec::new();
        v.extend_from_slice(&ty.to_le_bytes());
        v.extend_from_slice(&(data.len() as u32).to_le_bytes());
        v.extend_from_slice(data);
        v.resize(v.len().next_multiple_of(8), 0);
        v
    }

    /// The storage of one test column: (array class, data type, bytes of the values).
    pub(crate) fn stored(class: u32, values: &[f64]) -> (u32, Vec<u8>) {
        let mut d = Vec::new();
        let ty = match class {
            6 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&v.to_le_bytes()));
                MI_DOUBLE
            }
            7 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as f32).to_le_bytes()));
                MI_SINGLE
            }
            8 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as i8).to_le_bytes()));
                MI_INT8
            }
            9 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as u8).to_le_bytes()));
                MI_UINT8
            }
            10 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as i16).to_le_bytes()));
                MI_INT16
            }
            11 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as u16).to_le_bytes()));
                MI_UINT16
            }
            12 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as i32).to_le_bytes()));
                MI_INT32
            }
            13 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as u32).to_le_bytes()));
                MI_UINT32
            }
            14 => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as i64).to_le_bytes()));
                MI_INT64
            }
            _ => {
                values
                    .iter()
                    .for_each(|v| d.extend_from_slice(&(*v as u64).to_le_bytes()));
                MI_UINT64
            }
        };
        (ty, d)
    }

    /// A whole `.mat` file of row vectors `(name, class, values)` written as MATLAB
    /// and scipy write them; `compress`: each variable as `miCOMPRESSED`.
    pub(crate) fn mat_file(vars: &[(&str, u32, Vec<f64>)], compress: bool) -> Vec<u8> {
        let mut f = b"MATLAB 5.0 MAT-file, written by nanomotion's tests".to_vec();
        f.resize(116, b' ');
        f.extend_from_slice(&[0; 8]);
        f.extend_from_slice(&0x0100u16.to_le_bytes());
        f.extend_from_slice(b"IM");
        for (name, class, values) in vars {
            let (ty, data) = stored(*class, values);
            let mut body = element(MI_UINT32, &[&class.to_le_bytes()[..], &[0; 4]].concat());
            let dims = [1u32.to_le_bytes(), (values.len() as u32).to_le_bytes()].concat();
            body.extend(element(MI_INT32, &dims));
            body.extend(element(MI_INT8, name.as_bytes()));
            body.extend(element(ty, &data));
            let m = element(MI_MATRIX, &body);
            if compress {
                use std::io::Write;
                let mut enc = libflate::zlib::Encoder::new(Vec::new()).unwrap();
                enc.write_all(&m).unwrap();
                let z = enc.finish().into_result().unwrap();
                f.extend_from_slice(&MI_COMPRESSED.to_le_bytes());
                f.extend_from_slice(&(z.len() as u32).to_le_bytes());
                f.extend_from_slice(&z);
            } else {
                f.extend(m);
            }
        }
        f
    }

    #[test]
    fn every_integer_class_is_read_exactly() {
        let v: Vec<f64> = vec![0.0, 1.0, 7.0, 100.0, 127.0];
        let neg: Vec<f64> = vec![0.0, -1.0, -7.0, 100.0, -128.0];
        for class in 6..=15u32 {
            let signed = matches!(class, 6 | 7 | 8 | 10 | 12 | 14);
            let vals = if signed { neg.clone() } else { v.clone() };
            for compress in [false, true] {
                let bytes = mat_file(&[("x", class, vals.clone())], compress);
                let vars = read(&bytes, 1 << 20).unwrap();
                assert_eq!(vars.len(), 1, "class {class}");
                assert_eq!(vars[0].name, "x");
                assert_eq!(vars[0].dims, vec![1, 5]);
                assert_eq!(vars[0].values.as_ref().unwrap(), &vals, "class {class}");
            }
        }
        // 64-bit values beyond 2^53 are refused, not rounded.
        let mut f = mat_file(&[("x", 14, vec![0.0])], false);
        let at = f.len() - 8;
        f[at..].copy_from_slice(&((1i64 << 53) + 1).to_le_bytes());
        let e = read(&f, 1 << 20).unwrap();
        assert!(
            e[0].values.as_ref().unwrap_err().contains("no exact f64"),
            "{e:?}"
        );
    }

    proptest::proptest! {
        /// Any file cut at any byte is an error naming where it stops, never fewer
        /// variables; the whole file reads back every value bit for bit.
        #[test]
        fn cut_files_are_errors_and_whole_files_round_trip(
            cols in proptest::collection::vec((6u32..=15, proptest::collection::vec(-100i32..100, 1..40)), 1..4),
            compress in proptest::bool::ANY,
            cut in 0.0f64..1.0,
        ) {
            let vars: Vec<(String, u32, Vec<f64>)> = cols
                .iter()
                .enumerate()
                .map(|(i, (class, v))| {
                    let unsigned = matches!(class, 9 | 11 | 13 | 15);
                    let v = v.iter().map(|&x| if unsigned { x.unsigned_abs() as f64 } else { x as f64 }).collect();
                    (format!("v{i}"), *class, v)
                })
                .collect();
            let refs: Vec<(&str, u32, Vec<f64>)> = vars.iter().map(|(n, c, v)| (n.as_str(), *c, v.clone())).collect();
            let bytes = mat_file(&refs, compress);
            let back = read(&bytes, 1 << 20).unwrap();
            proptest::prop_assert_eq!(back.len(), vars.len());
            for (b, (n, _, v)) in back.iter().zip(&vars) {
                proptest::prop_assert_eq!(&b.name, n);
                proptest::prop_assert_eq!(b.values.as_ref().unwrap(), v);
            }
            let len = 129 + ((bytes.len() - 129) as f64 * cut) as usize;
            match read(&bytes[..len], 1 << 20) {
                // Cut exactly between two variables: indistinguishable from a
                // file of fewer variables, and those are read whole.
                Ok(got) => {
                    let k = got.len();
                    proptest::prop_assert_eq!(mat_file(&refs[..k], compress).len(), len);
                }
                Err(e) => {
                    proptest::prop_assert!(e.contains("cut off") || e.contains("damaged") || e.contains("decompressed"), "{}", e);
                    proptest::prop_assert!(e.contains("variable"), "{}", e);
                }
            }
        }
    }
}
