//! The checkpoint file format: a versioned header, named arrays with their types and shapes,
//! and a checksum over the whole file. It knows nothing of simulations: what a checkpoint
//! holds is said by [`crate::checkpoint`] and the `save`/`restore` of each part of the state.
//!
//! Layout (every integer little-endian; docs/checkpoints.md is the reference a reader outside
//! cellflip works from, with a numpy reader in `tools/checkpoint.py`):
//!
//! | bytes | what |
//! |---|---|
//! | 8 | magic `\x89CFCKPT\n` (a high byte and a newline, as PNG's, catch text-mode copies) |
//! | 4 | format version, [`VERSION`] |
//! | 4 | header length `H` |
//! | `H` | header: TOML, a `[meta]` table of strings and one `[[array]]` per array (`name`, numpy `dtype`, `shape`, `offset` from the file's start) |
//! | ... | the arrays' data, each starting at a multiple of [`ALIGN`] bytes, row-major |
//! | 4 | CRC-32 (IEEE, zlib's `crc32`) of every byte before it |
//! | 8 | end mark `CFCKEND\n` |
//!
//! Why not `.npz`: a zip archive needs zip64 records past 4 GiB (a 300^3 grid's velocity alone
//! is 650 MB, a checkpoint of a larger run passes 4 GiB) and checks each array on its own; this
//! layout is written in one pass, checked whole, and numpy still reads any array in one call
//! (`np.frombuffer(data, dtype, count, offset)`).

use crate::grid::Vector;
use bytemuck::{AnyBitPattern, NoUninit};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::Path;

#[cfg(target_endian = "big")]
compile_error!("checkpoints store arrays little-endian straight from memory");

/// The file's first bytes.
pub const MAGIC: &[u8; 8] = b"\x89CFCKPT\n";
/// Its last bytes, after the checksum.
pub const END: &[u8; 8] = b"CFCKEND\n";
/// The format's version: a reader refuses any other. 2 (2026-11-27): a checkpoint's scene holds
/// every method's table (ccp's `cross_check` among them) and no `cross_check` meta key; a version
/// 1 checkpoint would resume without the cross-check it was started with.
pub const VERSION: u32 = 2;
/// Arrays start at multiples of this many bytes (a cache line; numpy's `frombuffer` needs
/// only the item size).
pub const ALIGN: usize = 64;

/// Why a file could not be read as a checkpoint. The caller names the file.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SnapshotError {
    #[error("not a cellflip checkpoint (it does not start with the checkpoint magic)")]
    NotACheckpoint,
    #[error("truncated: {0}")]
    Truncated(String),
    #[error("corrupted: its checksum is {found:08x}, its data sums to {computed:08x}")]
    Checksum { found: u32, computed: u32 },
    #[error("format version {found}, this cellflip reads version {VERSION} only")]
    Version { found: u32 },
    #[error("its header is unreadable: {0}")]
    Header(String),
    #[error("it has no {0}")]
    Missing(String),
    #[error("{name}: {reason}")]
    Array { name: String, reason: String },
}

/// An element type an array may have, with its numpy dtype string.
pub trait Element: NoUninit + AnyBitPattern {
    const DTYPE: &'static str;
}

/// Each element type with its numpy dtype, and [`dtype_size`] read from the same list.
macro_rules! elements {
    ($($t:ty => $dtype:literal),*) => {
        $(impl Element for $t {
            const DTYPE: &'static str = $dtype;
        })*

        /// Bytes per element of a dtype this format writes.
        fn dtype_size(dtype: &str) -> Option<usize> {
            match dtype {
                $($dtype => Some(std::mem::size_of::<$t>()),)*
                _ => None,
            }
        }
    };
}

elements!(f64 => "<f8", u64 => "<u8", i64 => "<i8", u32 => "<u4", i32 => "<i4", u8 => "|u1");

/// One array to write, `len` bytes.
struct Entry<'a> {
    name: String,
    dtype: &'static str,
    shape: Vec<usize>,
    len: usize,
    data: Data<'a>,
}

/// An array's bytes: borrowed from the state where its memory layout is the file's, owned
/// where a small one had to be converted, or made while it is written where a large one has
/// to be (a copy of it held beside the state would raise a paper-scale run's peak).
enum Data<'a> {
    Bytes(Cow<'a, [u8]>),
    Made(Box<Made<'a>>),
}

/// Writes an array's bytes, a block at a time.
type Made<'a> = dyn Fn(&mut dyn Write) -> std::io::Result<()> + 'a;

/// Elements a made array converts at a time (512 KiB of `f64`).
const BLOCK: usize = 1 << 16;

/// A checkpoint being put together: its metadata and arrays, written by [`Writer::write_to`].
#[derive(Default)]
pub struct Writer<'a> {
    meta: BTreeMap<String, String>,
    arrays: Vec<Entry<'a>>,
}

impl<'a> Writer<'a> {
    /// A metadata string (what made the file, the scene as run).
    pub fn meta(&mut self, key: &str, value: impl Into<String>) {
        self.meta.insert(key.into(), value.into());
    }

    /// An array of `shape` (its product is `data.len()`), borrowed.
    pub fn array<T: Element>(&mut self, name: &str, shape: &[usize], data: &'a [T]) {
        let bytes = Cow::Borrowed(bytemuck::cast_slice(data));
        self.entry::<T>(name, shape, data.len(), Data::Bytes(bytes));
    }

    /// A one-dimensional array, borrowed.
    pub fn slice<T: Element>(&mut self, name: &str, data: &'a [T]) {
        self.array(name, &[data.len()], data);
    }

    /// A small array of `shape`, owned (its bytes are copied once).
    pub fn owned<T: Element>(&mut self, name: &str, shape: &[usize], data: Vec<T>) {
        let bytes = Cow::Owned(bytemuck::cast_slice::<T, u8>(&data).to_vec());
        self.entry::<T>(name, shape, data.len(), Data::Bytes(bytes));
    }

    /// An array of `shape` whose elements `elements()` yields in order, converted a block at
    /// a time while the file is written: a large array stored otherwise than the file stores
    /// it (the particles' vectors, the markings' depths) is never copied whole.
    pub fn made<T: Element, I: Iterator<Item = T>>(
        &mut self,
        name: &str,
        shape: &[usize],
        elements: impl Fn() -> I + 'a,
    ) {
        let (want, label) = (shape.iter().product::<usize>(), name.to_string());
        let write = move |w: &mut dyn Write| {
            let (mut block, mut n) = (Vec::with_capacity(BLOCK.min(want)), 0);
            for x in elements() {
                block.push(x);
                if block.len() == BLOCK {
                    w.write_all(bytemuck::cast_slice(&block))?;
                    n += block.len();
                    block.clear();
                }
            }
            w.write_all(bytemuck::cast_slice(&block))?;
            assert_eq!(
                n + block.len(),
                want,
                "{label}: elements made for its shape"
            );
            Ok(())
        };
        self.entry::<T>(name, shape, want, Data::Made(Box::new(write)));
    }

    /// A scalar (a numpy array of shape `()`).
    pub fn scalar<T: Element>(&mut self, name: &str, x: T) {
        self.owned(name, &[], vec![x]);
    }

    /// The `n` vectors `v()` yields as an `n x D` array of `<f8`, made while written.
    pub fn vectors<const D: usize, I: Iterator<Item = &'a Vector<D>>>(
        &mut self,
        name: &str,
        n: usize,
        v: impl Fn() -> I + 'a,
    ) {
        self.made(name, &[n, D], move || v().flat_map(|x| x.iter().copied()));
    }

    /// Flags as bytes 0 and 1, borrowed.
    pub fn bools(&mut self, name: &str, v: &'a [bool]) {
        let bytes: &[u8] = bytemuck::cast_slice(v);
        self.array(name, &[v.len()], bytes);
    }

    fn entry<T: Element>(&mut self, name: &str, shape: &[usize], n: usize, data: Data<'a>) {
        assert_eq!(
            shape.iter().product::<usize>(),
            n,
            "{name}: shape {shape:?}"
        );
        assert!(
            self.arrays.iter().all(|e| e.name != name),
            "{name} written twice"
        );
        self.arrays.push(Entry {
            name: name.into(),
            dtype: T::DTYPE,
            shape: shape.to_vec(),
            len: n * std::mem::size_of::<T>(),
            data,
        });
    }

    /// The header, with every array's offset for a data section starting at `start`.
    fn header(&self, start: usize) -> String {
        let mut t = toml::Table::new();
        let meta = self.meta.iter().map(|(k, v)| (k.clone(), v.clone().into()));
        t.insert("meta".into(), toml::Value::Table(meta.collect()));
        let mut at = start;
        let arrays = self.arrays.iter().map(|e| {
            let mut a = toml::Table::new();
            a.insert("name".into(), e.name.clone().into());
            a.insert("dtype".into(), e.dtype.into());
            let shape = e.shape.iter().map(|&n| toml::Value::Integer(n as i64));
            a.insert("shape".into(), toml::Value::Array(shape.collect()));
            a.insert("offset".into(), toml::Value::Integer(at as i64));
            at = align(at + e.len);
            toml::Value::Table(a)
        });
        t.insert("array".into(), toml::Value::Array(arrays.collect()));
        toml::to_string(&t).expect("a table of strings and integers serialises")
    }

    /// Writes the file to `w` (buffer it); returns the bytes written.
    pub fn write_to(&self, w: impl Write) -> std::io::Result<u64> {
        // The header's length depends on the offsets, which depend on its length: offsets are
        // padded to ALIGN, so a fixed point is reached in a few rounds.
        let mut start = align(16);
        let header = loop {
            let h = self.header(start);
            let need = align(16 + h.len());
            if need == start {
                break h;
            }
            start = need;
        };
        let mut w = Summing::new(w);
        w.write_all(MAGIC)?;
        w.write_all(&VERSION.to_le_bytes())?;
        w.write_all(&(header.len() as u32).to_le_bytes())?;
        w.write_all(header.as_bytes())?;
        for e in &self.arrays {
            w.pad_to(align(w.len as usize))?;
            match &e.data {
                Data::Bytes(b) => w.write_all(b)?,
                Data::Made(write) => write(&mut w)?,
            }
        }
        let crc = w.crc.clone().finalize();
        w.inner.write_all(&crc.to_le_bytes())?;
        w.inner.write_all(END)?;
        w.inner.flush()?;
        Ok(w.len + 12)
    }
}

impl Writer<'_> {
    /// Writes the file at `path` so that no reader ever sees it half-written: to
    /// `.NAME.partial` beside it, synced, renamed, and the folder synced. On failure the
    /// partial file is removed and whatever was at `path` is untouched.
    pub fn write_file(&self, path: &Path) -> std::io::Result<u64> {
        let name = path
            .file_name()
            .map_or_else(Default::default, |n| n.to_string_lossy());
        let partial = path.with_file_name(format!(".{name}.partial"));
        let written = (|| {
            let mut out = std::io::BufWriter::with_capacity(8 << 20, File::create(&partial)?);
            let n = self.write_to(&mut out)?;
            out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
            std::fs::rename(&partial, path)?;
            let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
            File::open(dir.unwrap_or(Path::new(".")))?.sync_all()?;
            Ok(n)
        })();
        if written.is_err() {
            let _ = std::fs::remove_file(&partial);
        }
        written
    }
}

/// `at` rounded up to [`ALIGN`].
fn align(at: usize) -> usize {
    at.div_ceil(ALIGN) * ALIGN
}

/// The CRC-32 of what `r` reads, a MiB at a time (the binary's, hundreds of MB with its debug
/// information, read whole would be the peak of a run's first checkpoint).
pub fn crc_of(r: impl std::io::Read) -> std::io::Result<u32> {
    let mut sum = Summing::new(std::io::sink());
    std::io::copy(&mut std::io::BufReader::with_capacity(1 << 20, r), &mut sum)?;
    Ok(sum.crc.finalize())
}

/// A writer that sums what passes through it.
struct Summing<W: Write> {
    inner: W,
    crc: crc32fast::Hasher,
    len: u64,
}

impl<W: Write> Summing<W> {
    fn new(inner: W) -> Self {
        let crc = crc32fast::Hasher::new();
        Self { inner, crc, len: 0 }
    }

    fn pad_to(&mut self, at: usize) -> std::io::Result<()> {
        let zeros = vec![0u8; at - self.len as usize];
        self.write_all(&zeros)
    }
}

impl<W: Write> Write for Summing<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.len += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Where an array lies in a file read.
#[derive(Clone, Debug)]
struct Located {
    dtype: String,
    shape: Vec<usize>,
    offset: usize,
}

/// A checkpoint read whole and checked: its metadata and its arrays by name.
pub struct Reader {
    bytes: Vec<u8>,
    meta: BTreeMap<String, String>,
    arrays: BTreeMap<String, Located>,
}

impl Reader {
    /// Checks the magic, the version, the checksum and the header of a file's bytes.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self, SnapshotError> {
        if bytes.len() < 8 || &bytes[..8] != MAGIC {
            return Err(SnapshotError::NotACheckpoint);
        }
        if bytes.len() < 16 + 12 {
            return Err(SnapshotError::Truncated(format!("{} bytes", bytes.len())));
        }
        let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        let version = u32_at(8);
        if version != VERSION {
            return Err(SnapshotError::Version { found: version });
        }
        let body = bytes.len() - 12;
        if &bytes[body + 4..] != END {
            return Err(SnapshotError::Truncated(format!(
                "{} bytes and no end mark (the write did not finish)",
                bytes.len()
            )));
        }
        let (found, computed) = (u32_at(body), crc32fast::hash(&bytes[..body]));
        if found != computed {
            return Err(SnapshotError::Checksum { found, computed });
        }
        let header_len = u32_at(12) as usize;
        let header = bytes
            .get(16..16 + header_len)
            .ok_or_else(|| SnapshotError::Header("longer than the file".into()))?;
        let (meta, arrays) = parse_header(header, body)?;
        Ok(Self {
            bytes,
            meta,
            arrays,
        })
    }

    /// A metadata string.
    pub fn meta(&self, key: &str) -> Result<&str, SnapshotError> {
        (self.meta.get(key).map(String::as_str))
            .ok_or_else(|| SnapshotError::Missing(format!("meta.{key}")))
    }

    /// Frees the arrays' data (once the state is restored from them); the metadata stays.
    pub fn release(&mut self) {
        self.bytes = Vec::new();
        self.arrays.clear();
    }

    /// Whether it holds an array of this name.
    pub fn has(&self, name: &str) -> bool {
        self.arrays.contains_key(name)
    }

    /// The array `name` of element type `T`, and its shape.
    pub fn array<T: Element>(&self, name: &str) -> Result<(Vec<T>, Vec<usize>), SnapshotError> {
        let a = (self.arrays.get(name)).ok_or_else(|| SnapshotError::Missing(name.into()))?;
        if a.dtype != T::DTYPE {
            return Err(array_error(
                name,
                format!("dtype {}, expected {}", a.dtype, T::DTYPE),
            ));
        }
        let n: usize = a.shape.iter().product();
        let mut out = vec![T::zeroed(); n];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        dst.copy_from_slice(&self.bytes[a.offset..a.offset + dst.len()]);
        Ok((out, a.shape.clone()))
    }

    /// A one-dimensional array of `len` elements (any length with `None`).
    pub fn slice<T: Element>(
        &self,
        name: &str,
        len: Option<usize>,
    ) -> Result<Vec<T>, SnapshotError> {
        let (v, shape) = self.array::<T>(name)?;
        match (shape.as_slice(), len) {
            ([n], Some(want)) if *n != want => {
                Err(array_error(name, format!("{n} elements, expected {want}")))
            }
            ([_], _) => Ok(v),
            (s, _) => Err(array_error(name, format!("shape {s:?}, expected one axis"))),
        }
    }

    /// A scalar.
    pub fn scalar<T: Element>(&self, name: &str) -> Result<T, SnapshotError> {
        match self.array::<T>(name)? {
            (v, s) if s.is_empty() => Ok(v[0]),
            (_, s) => Err(array_error(name, format!("shape {s:?}, expected a scalar"))),
        }
    }

    /// An `n x D` array as vectors (`n` checked when given).
    pub fn vectors<const D: usize>(
        &self,
        name: &str,
        len: Option<usize>,
    ) -> Result<Vec<Vector<D>>, SnapshotError> {
        let (v, shape) = self.array::<f64>(name)?;
        match shape.as_slice() {
            [n, d] if *d == D && len.is_none_or(|want| want == *n) => Ok(v
                .chunks_exact(D)
                .map(Vector::<D>::from_column_slice)
                .collect()),
            s => Err(array_error(
                name,
                format!("shape {s:?}, expected [{len:?}, {D}]"),
            )),
        }
    }

    /// Flags stored as bytes 0 and 1.
    pub fn bools(&self, name: &str, len: Option<usize>) -> Result<Vec<bool>, SnapshotError> {
        let v = self.slice::<u8>(name, len)?;
        v.iter()
            .map(|&b| match b {
                0 => Ok(false),
                1 => Ok(true),
                b => Err(array_error(name, format!("a flag is {b}, not 0 or 1"))),
            })
            .collect()
    }
}

/// Checks what a checkpoint's array holds, not only its shape: the first element for which
/// `why` gives a reason fails the read, naming the array, the element and the reason. A
/// checksum proves the bytes are those written, not that they make a state (a file edited with
/// numpy and its checksum recomputed).
pub fn check_elements<T: Sync>(
    name: &str,
    items: &[T],
    why: impl Fn(&T) -> Option<String> + Sync,
) -> Result<(), SnapshotError> {
    check_indices(name, items.len(), |i| why(&items[i]))
}

/// As [`check_elements`] over elements `0..n` given by index, for a check that reads several
/// arrays at the same element (a cell's kind beside its count).
pub fn check_indices(
    name: &str,
    n: usize,
    why: impl Fn(usize) -> Option<String> + Sync,
) -> Result<(), SnapshotError> {
    use rayon::prelude::*;
    let first = (0..n)
        .into_par_iter()
        .with_min_len(crate::PAR_GRAIN_PARTICLES)
        .find_map_first(|i| why(i).map(|w| (i, w)));
    match first {
        None => Ok(()),
        Some((i, why)) => Err(array_error(name, format!("element {i}: {why}"))),
    }
}

/// A scalar of a checkpoint, `x`, taken when `ok`; else the read fails saying what it `must` be.
pub fn check_scalar(name: &str, x: f64, ok: bool, must: &str) -> Result<f64, SnapshotError> {
    match ok {
        true => Ok(x),
        false => Err(array_error(name, format!("is {x}, must be {must}"))),
    }
}

/// [`check_elements`]' reason for a number that is not finite.
pub fn not_finite(x: &f64) -> Option<String> {
    (!x.is_finite()).then(|| format!("{x} is not a finite number"))
}

/// [`check_elements`]' reason for a vector with a component that is not finite.
pub fn vector_not_finite<const D: usize>(x: &Vector<D>) -> Option<String> {
    (!x.iter().all(|c| c.is_finite())).then(|| format!("{:?} is not finite", x.as_slice()))
}

fn array_error(name: &str, reason: String) -> SnapshotError {
    SnapshotError::Array {
        name: name.into(),
        reason,
    }
}

type Header = (BTreeMap<String, String>, BTreeMap<String, Located>);

/// The header's metadata and arrays, each array checked to lie within the data (`end`: where
/// the checksum starts).
fn parse_header(header: &[u8], end: usize) -> Result<Header, SnapshotError> {
    let bad = |e: &dyn std::fmt::Display| SnapshotError::Header(e.to_string());
    let text = std::str::from_utf8(header).map_err(|e| bad(&e))?;
    let t: toml::Table = toml::from_str(text).map_err(|e| bad(&e))?;
    let meta = match t.get("meta") {
        Some(toml::Value::Table(m)) => m
            .iter()
            .map(|(k, v)| match v {
                toml::Value::String(s) => Ok((k.clone(), s.clone())),
                _ => Err(bad(&format!("meta.{k} is not a string"))),
            })
            .collect::<Result<_, _>>()?,
        _ => return Err(bad(&"no [meta] table")),
    };
    let mut arrays = BTreeMap::new();
    let list = match t.get("array") {
        Some(toml::Value::Array(a)) => a.as_slice(),
        None => &[],
        Some(_) => return Err(bad(&"`array` is not a list of tables")),
    };
    for a in list {
        let (name, located) = parse_array(a)?;
        let size = dtype_size(&located.dtype)
            .ok_or_else(|| bad(&format!("{name}: unknown dtype {}", located.dtype)))?;
        let bytes = size * located.shape.iter().product::<usize>();
        if located.offset.checked_add(bytes).is_none_or(|e| e > end) {
            return Err(SnapshotError::Truncated(format!(
                "{name} runs past the data"
            )));
        }
        arrays.insert(name, located);
    }
    Ok((meta, arrays))
}

/// One `[[array]]` entry.
fn parse_array(a: &toml::Value) -> Result<(String, Located), SnapshotError> {
    let bad = |what: String| SnapshotError::Header(what);
    let get = |k: &str| {
        a.get(k)
            .ok_or_else(|| bad(format!("an array has no `{k}`")))
    };
    let name = (get("name")?.as_str()).ok_or_else(|| bad("a name is not a string".into()))?;
    let field = |k: &str| bad(format!("{name}: {k}"));
    let dtype = get("dtype")?.as_str().ok_or_else(|| field("dtype"))?;
    let uint = |v: &toml::Value| v.as_integer().and_then(|i| usize::try_from(i).ok());
    let shape = (get("shape")?.as_array())
        .and_then(|s| s.iter().map(uint).collect::<Option<Vec<usize>>>())
        .ok_or_else(|| field("shape"))?;
    let offset = uint(get("offset")?).ok_or_else(|| field("offset"))?;
    let located = Located {
        dtype: dtype.into(),
        shape,
        offset,
    };
    Ok((name.into(), located))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        let f = [1.5, -2.0, f64::MIN_POSITIVE, 0.1];
        let flags = [true, false, true];
        let x = [Vector::<3>::new(1.0, 2.0, 3.0)];
        let mut w = Writer::default();
        w.meta("scene", "dam-2d");
        w.array("f", &[2, 2], &f);
        w.bools("flags", &flags);
        w.scalar("t", 0.3f64);
        w.vectors("x", x.len(), || x.iter());
        w.slice::<u32>("empty", &[]);
        // Over two blocks, so that a block's end and a partial last block are both written.
        w.made("made", &[2 * BLOCK + 3], || {
            (0..2 * BLOCK as u32 + 3).map(|i| i ^ 0x5a5a)
        });
        let mut out = vec![];
        let n = w.write_to(&mut out).unwrap();
        assert_eq!(n, out.len() as u64);
        out
    }

    #[test]
    fn what_is_written_reads_back_bit_for_bit() {
        let r = Reader::from_bytes(sample()).unwrap();
        assert_eq!(r.meta("scene").unwrap(), "dam-2d");
        let (f, shape) = r.array::<f64>("f").unwrap();
        assert_eq!(shape, [2, 2]);
        let bits: Vec<u64> = f.iter().map(|x| x.to_bits()).collect();
        let want = [1.5, -2.0, f64::MIN_POSITIVE, 0.1].map(f64::to_bits);
        assert_eq!(bits, want);
        assert_eq!(r.bools("flags", Some(3)).unwrap(), [true, false, true]);
        assert_eq!(r.scalar::<f64>("t").unwrap(), 0.3);
        assert_eq!(
            r.vectors::<3>("x", Some(1)).unwrap()[0],
            Vector::<3>::new(1.0, 2.0, 3.0)
        );
        assert!(r.slice::<u32>("empty", Some(0)).unwrap().is_empty());
        let made = r.slice::<u32>("made", Some(2 * BLOCK + 3)).unwrap();
        assert!(made
            .iter()
            .enumerate()
            .all(|(i, &x)| x == i as u32 ^ 0x5a5a));
        assert_eq!(
            r.meta("nothing"),
            Err(SnapshotError::Missing("meta.nothing".into()))
        );
        // Each array starts at a multiple of ALIGN.
        assert!(r.arrays.values().all(|a| a.offset % ALIGN == 0));
    }

    /// A CRC read a block at a time is that of the bytes read whole.
    #[test]
    fn a_readers_crc_is_that_of_its_bytes() {
        let bytes: Vec<u8> = (0..5u32 << 19).map(|i| ((i * 7919) >> 3) as u8).collect();
        assert_eq!(crc_of(&bytes[..]).unwrap(), crc32fast::hash(&bytes));
    }

    /// A made array yields exactly its shape's elements, or the write stops (a file whose
    /// offsets no longer match its data would pass its checksum).
    #[test]
    #[should_panic(expected = "short: elements made for its shape")]
    fn a_made_array_short_of_its_shape_is_not_written() {
        let mut w = Writer::default();
        w.made("short", &[3], || [1.0f64, 2.0].into_iter());
        let _ = w.write_to(vec![]);
    }

    #[test]
    fn a_wrong_type_or_shape_is_refused_by_name() {
        let r = Reader::from_bytes(sample()).unwrap();
        let e = r.array::<u32>("f").unwrap_err().to_string();
        assert_eq!(e, "f: dtype <f8, expected <u4");
        let e = r.slice::<f64>("f", None).unwrap_err().to_string();
        assert_eq!(e, "f: shape [2, 2], expected one axis");
        assert!(r.bools("flags", Some(4)).is_err());
        assert!(r.vectors::<2>("x", None).is_err());
    }

    #[test]
    fn damage_of_any_kind_is_named() {
        let good = sample();
        let read = |b: Vec<u8>| Reader::from_bytes(b).err();
        assert_eq!(
            read(b"hello world, not a checkpoint".to_vec()),
            Some(SnapshotError::NotACheckpoint)
        );
        // Truncated anywhere: no end mark.
        for cut in [20, good.len() / 2, good.len() - 1] {
            assert!(
                matches!(
                    read(good[..cut].to_vec()),
                    Some(SnapshotError::Truncated(_))
                ),
                "cut at {cut}"
            );
        }
        // One bit flipped in the data or the header: the checksum.
        for at in [20, good.len() - 20] {
            let mut b = good.clone();
            b[at] ^= 0x10;
            assert!(
                matches!(read(b), Some(SnapshotError::Checksum { .. })),
                "flip at {at}"
            );
        }
        for old in [1, 7] {
            let mut b = good.clone();
            b[8] = old;
            assert_eq!(read(b), Some(SnapshotError::Version { found: old.into() }));
        }
    }
}
