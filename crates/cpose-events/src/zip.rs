//! A small ZIP reader and writer, enough for NumPy's `.npz` archives (`np.savez`,
//! `np.savez_compressed`).
//!
//! Reading follows the central directory (not the local headers' sizes, which numpy leaves as
//! ZIP64 placeholders): the end-of-central-directory record (and the ZIP64 one when counts or
//! offsets overflow 16/32 bits), then one central header per entry with its method, CRC-32,
//! sizes and the offset of its local header, whose name and extra lengths locate the data.
//! Entries are STORED (method 0) or DEFLATE (method 8, inflated with `miniz_oxide`); the size
//! and CRC-32 of every entry are checked. Encrypted entries, other methods and multi-disk
//! archives are rejected.
//!
//! Writing produces STORED entries with CRC-32 (`crc32fast`) and a fixed time stamp
//! (1980-01-01 00:00), so the same entries give the same bytes. Entries and the archive must stay
//! below 4 GiB (no ZIP64 on writing).
//!
//! Record layouts are those of PKWARE's APPNOTE.TXT, sections 4.3.7 (local header), 4.3.12
//! (central header), 4.3.14–4.3.16 (ZIP64 end records and end of central directory) and 4.5.3
//! (ZIP64 extra field).

/// A failure to read a ZIP archive, as "expected …, got …" (the caller adds the file name).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("expected {expected}, got {found}")]
pub struct ZipError {
    /// What the reader expected.
    pub expected: String,
    /// What it found.
    pub found: String,
}

fn zip_err(expected: impl Into<String>, found: impl Into<String>) -> ZipError {
    ZipError {
        expected: expected.into(),
        found: found.into(),
    }
}

const LOCAL_SIG: u32 = 0x0403_4b50;
const CENTRAL_SIG: u32 = 0x0201_4b50;
const END_SIG: u32 = 0x0605_4b50;
const ZIP64_END_SIG: u32 = 0x0606_4b50;
const ZIP64_LOCATOR_SIG: u32 = 0x0706_4b50;
/// Header ID of the ZIP64 extended-information extra field.
const ZIP64_EXTRA_ID: u16 = 0x0001;
/// Length of the end-of-central-directory record without its comment.
const END_LEN: usize = 22;
/// Largest comment of the end record (its length field is 16 bits).
const MAX_COMMENT: usize = u16::MAX as usize;
/// DEFLATE's largest expansion (a run of one byte: 258 bytes per 2 bits, about 1032 : 1). An
/// entry that declares more is a forged header, refused before anything is inflated.
const MAX_DEFLATE_RATIO: u64 = 1032;
/// The most bytes an archive inflates to in all (8 GiB): sizes are checked before they are
/// allocated.
pub const MAX_UNCOMPRESSED: u64 = 8 << 30;
/// DOS date of 1980-01-01 (`(year − 1980) << 9 | month << 5 | day`).
const DOS_DATE_1980: u16 = (1 << 5) | 1;
/// "Version needed to extract" / "made by": 2.0, the version that introduced DEFLATE.
const VERSION_20: u16 = 20;

/// Little-endian reads at offsets, failing with a [`ZipError`] past the end.
struct Reader<'a> {
    bytes: &'a [u8],
}

impl Reader<'_> {
    fn slice(&self, at: usize, len: usize, what: &str) -> Result<&[u8], ZipError> {
        at.checked_add(len)
            .and_then(|end| self.bytes.get(at..end))
            .ok_or_else(|| {
                zip_err(
                    format!("{what} ({len} bytes at offset {at})"),
                    format!("an archive of {} bytes", self.bytes.len()),
                )
            })
    }
    fn u16(&self, at: usize, what: &str) -> Result<u16, ZipError> {
        let b = self.slice(at, 2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&self, at: usize, what: &str) -> Result<u32, ZipError> {
        let b = self.slice(at, 4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&self, at: usize, what: &str) -> Result<u64, ZipError> {
        let b = self.slice(at, 8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }
}

fn to_usize(v: u64, what: &str) -> Result<usize, ZipError> {
    usize::try_from(v).map_err(|_| zip_err(format!("{what} addressable in memory"), v.to_string()))
}

/// The central directory: `(offset, number of entries)`.
fn central_directory(r: &Reader<'_>) -> Result<(usize, usize), ZipError> {
    let n = r.bytes.len();
    let lowest = n.saturating_sub(END_LEN + MAX_COMMENT);
    let end = (lowest..=n.saturating_sub(END_LEN))
        .rev()
        // The last signature whose record and comment fit in the file.
        .find(|&i| {
            r.u32(i, "").is_ok_and(|s| s == END_SIG)
                && r.u16(i + 20, "")
                    .is_ok_and(|c| i + END_LEN + usize::from(c) <= n)
        })
        .ok_or_else(|| {
            zip_err(
                "a ZIP archive (an end-of-central-directory record)",
                format!("{n} bytes without one"),
            )
        })?;
    let disk = r.u16(end + 4, "end record")?;
    let cd_disk = r.u16(end + 6, "end record")?;
    if disk != 0 || cd_disk != 0 {
        return Err(zip_err(
            "a single-disk archive",
            format!("disk {disk}, central directory on disk {cd_disk}"),
        ));
    }
    let entries = r.u16(end + 10, "end record")?;
    let cd_offset = r.u32(end + 16, "end record")?;
    if entries != u16::MAX && cd_offset != u32::MAX {
        return Ok((cd_offset as usize, usize::from(entries)));
    }
    // ZIP64: the locator sits just before the end record and points at the ZIP64 end record.
    let locator = end.checked_sub(20).ok_or_else(|| {
        zip_err(
            "a ZIP64 end-of-central-directory locator before the end record",
            "nothing",
        )
    })?;
    if r.u32(locator, "ZIP64 locator")? != ZIP64_LOCATOR_SIG {
        return Err(zip_err(
            "a ZIP64 end-of-central-directory locator (the end record holds 0xFFFF…)",
            format!("signature {:#010x}", r.u32(locator, "ZIP64 locator")?),
        ));
    }
    let end64 = to_usize(r.u64(locator + 8, "ZIP64 locator")?, "ZIP64 end offset")?;
    if r.u32(end64, "ZIP64 end record")? != ZIP64_END_SIG {
        return Err(zip_err(
            format!("a ZIP64 end-of-central-directory record at offset {end64}"),
            format!("signature {:#010x}", r.u32(end64, "ZIP64 end record")?),
        ));
    }
    let entries = to_usize(r.u64(end64 + 32, "ZIP64 end record")?, "entry count")?;
    let cd_offset = to_usize(r.u64(end64 + 48, "ZIP64 end record")?, "directory offset")?;
    Ok((cd_offset, entries))
}

/// Reads every entry of a ZIP archive: `(name, uncompressed bytes)` in directory order, at most
/// [`MAX_UNCOMPRESSED`] bytes in all.
pub fn read_zip(bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, ZipError> {
    read_zip_with_limit(bytes, MAX_UNCOMPRESSED)
}

/// [`read_zip`] with at most `limit` bytes uncompressed, checked against the declared sizes
/// before anything is inflated.
fn read_zip_with_limit(bytes: &[u8], limit: u64) -> Result<Vec<(String, Vec<u8>)>, ZipError> {
    let r = Reader { bytes };
    let (mut at, count) = central_directory(&r)?;
    let mut entries = Vec::with_capacity(count.min(1024));
    let mut total = 0u64;
    for k in 0..count {
        let what = format!("central header {k}");
        let sig = r.u32(at, &what)?;
        if sig != CENTRAL_SIG {
            return Err(zip_err(
                format!("{what} (signature 0x02014b50) at offset {at}"),
                format!("signature {sig:#010x}"),
            ));
        }
        let flags = r.u16(at + 8, &what)?;
        let method = r.u16(at + 10, &what)?;
        let crc = r.u32(at + 16, &what)?;
        let mut compressed = u64::from(r.u32(at + 20, &what)?);
        let mut size = u64::from(r.u32(at + 24, &what)?);
        let name_len = usize::from(r.u16(at + 28, &what)?);
        let extra_len = usize::from(r.u16(at + 30, &what)?);
        let comment_len = usize::from(r.u16(at + 32, &what)?);
        let mut local = u64::from(r.u32(at + 42, &what)?);
        let name = String::from_utf8_lossy(r.slice(at + 46, name_len, &what)?).into_owned();
        let extra = r.slice(at + 46 + name_len, extra_len, &what)?;
        read_zip64_extra(extra, &mut size, &mut compressed, &mut local, &name)?;
        at += 46 + name_len + extra_len + comment_len;

        if flags & 1 != 0 {
            return Err(zip_err(
                format!("entry {name:?} unencrypted"),
                "an encrypted entry",
            ));
        }
        let local = to_usize(local, "local header offset")?;
        let lwhat = format!("local header of {name:?}");
        if r.u32(local, &lwhat)? != LOCAL_SIG {
            return Err(zip_err(
                format!("{lwhat} (signature 0x04034b50) at offset {local}"),
                format!("signature {:#010x}", r.u32(local, &lwhat)?),
            ));
        }
        let data_at = local
            + 30
            + usize::from(r.u16(local + 26, &lwhat)?)
            + usize::from(r.u16(local + 28, &lwhat)?);
        let raw = r.slice(
            data_at,
            to_usize(compressed, "compressed size")?,
            &format!("data of {name:?}"),
        )?;
        if method == 8
            && size
                > compressed
                    .saturating_mul(MAX_DEFLATE_RATIO)
                    .saturating_add(64)
        {
            return Err(zip_err(
                format!(
                    "entry {name:?}: an uncompressed size at most {MAX_DEFLATE_RATIO} times its \
                     {compressed} compressed bytes"
                ),
                format!("{size} bytes declared (a forged header)"),
            ));
        }
        total = total.saturating_add(size);
        if total > limit {
            return Err(zip_err(
                format!("an archive of at most {limit} bytes uncompressed"),
                format!("{total} bytes up to entry {name:?}"),
            ));
        }
        let size = to_usize(size, "uncompressed size")?;
        let data = match method {
            0 => raw.to_vec(),
            8 => miniz_oxide::inflate::decompress_to_vec_with_limit(raw, size).map_err(|e| {
                zip_err(
                    format!("entry {name:?}: DEFLATE data of {size} bytes"),
                    format!("an inflate error ({:?})", e.status),
                )
            })?,
            m => {
                return Err(zip_err(
                    format!("entry {name:?} STORED (0) or DEFLATE (8)"),
                    format!("compression method {m}"),
                ));
            }
        };
        if data.len() != size {
            return Err(zip_err(
                format!("entry {name:?}: {size} bytes"),
                format!("{} bytes", data.len()),
            ));
        }
        let actual = crc32fast::hash(&data);
        if actual != crc {
            return Err(zip_err(
                format!("entry {name:?}: CRC-32 {crc:#010x}"),
                format!("{actual:#010x} (corrupt data)"),
            ));
        }
        entries.push((name, data));
    }
    Ok(entries)
}

/// Replaces the 32-bit fields that hold `0xFFFFFFFF` by their values in the ZIP64 extra field
/// (which lists, in this order, only the overflowed ones: size, compressed size, offset).
fn read_zip64_extra(
    extra: &[u8],
    size: &mut u64,
    compressed: &mut u64,
    local: &mut u64,
    name: &str,
) -> Result<(), ZipError> {
    let mut fields: Vec<&mut u64> = [size, compressed, local]
        .into_iter()
        .filter(|v| **v == u64::from(u32::MAX))
        .collect();
    if fields.is_empty() {
        return Ok(());
    }
    let r = Reader { bytes: extra };
    let mut at = 0;
    while at + 4 <= extra.len() {
        let id = r.u16(at, "extra field")?;
        let len = usize::from(r.u16(at + 2, "extra field")?);
        if id == ZIP64_EXTRA_ID {
            for (k, field) in fields.iter_mut().enumerate() {
                **field = r.u64(at + 4 + 8 * k, &format!("ZIP64 extra field of {name:?}"))?;
            }
            return Ok(());
        }
        at += 4 + len;
    }
    Err(zip_err(
        format!("entry {name:?}: a ZIP64 extra field for its 0xFFFFFFFF sizes"),
        "none",
    ))
}

/// A ZIP archive of STORED entries `(name, bytes)` (see the module docs). Errors if an entry,
/// a name or the archive reaches 4 GiB (no ZIP64), or there are 65535 entries or more.
pub fn write_zip(entries: &[(&str, &[u8])]) -> Result<Vec<u8>, ZipError> {
    let too_big =
        |what: String| zip_err(format!("{what} below 4 GiB (ZIP64 is not written)"), "more");
    if entries.len() >= usize::from(u16::MAX) {
        return Err(zip_err(
            "fewer than 65535 entries (ZIP64 is not written)",
            entries.len().to_string(),
        ));
    }
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let size = u32::try_from(data.len()).map_err(|_| too_big(format!("entry {name:?}")))?;
        let name_len = u16::try_from(name.len())
            .map_err(|_| zip_err("entry names below 64 KiB", name.len().to_string()))?;
        let offset = u32::try_from(out.len()).map_err(|_| too_big("the archive".into()))?;
        let crc = crc32fast::hash(data);
        // Shared by the local and the central header, from "version needed" to the name length.
        let mut common = Vec::with_capacity(24);
        for v in [VERSION_20, 0, 0, 0, DOS_DATE_1980] {
            common.extend_from_slice(&v.to_le_bytes()); // version, flags, method, time, date
        }
        for v in [crc, size, size] {
            common.extend_from_slice(&v.to_le_bytes());
        }
        common.extend_from_slice(&name_len.to_le_bytes());

        out.extend_from_slice(&LOCAL_SIG.to_le_bytes());
        out.extend_from_slice(&common);
        out.extend_from_slice(&0u16.to_le_bytes()); // extra length
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(data);

        central.extend_from_slice(&CENTRAL_SIG.to_le_bytes());
        central.extend_from_slice(&VERSION_20.to_le_bytes()); // made by
        central.extend_from_slice(&common);
        // Extra and comment lengths, disk, internal attributes (2 bytes each), external
        // attributes (4).
        central.extend_from_slice(&[0u8; 12]);
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
    }
    let cd_offset = u32::try_from(out.len()).map_err(|_| too_big("the archive".into()))?;
    let cd_size = u32::try_from(central.len()).map_err(|_| too_big("the directory".into()))?;
    out.extend_from_slice(&central);
    let count = u16::try_from(entries.len()).expect("checked above");
    out.extend_from_slice(&END_SIG.to_le_bytes());
    out.extend_from_slice(&[0u8; 4]); // this disk, directory disk
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&cd_size.to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes()); // comment length
    u32::try_from(out.len()).map_err(|_| too_big("the archive".into()))?;
    Ok(out)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// One entry of [`zip_with`].
    pub(crate) struct TestEntry<'a> {
        pub name: &'a str,
        pub data: &'a [u8],
        pub deflate: bool,
        /// Write the central sizes and offset as 0xFFFFFFFF with a ZIP64 extra field, as for huge
        /// entries.
        pub zip64: bool,
    }

    /// A ZIP archive built independently of [`write_zip`]: DEFLATE entries compressed with
    /// miniz_oxide, optional ZIP64 extra fields and a ZIP64 end record, a local header with
    /// placeholder sizes (as numpy writes them) and an archive comment.
    pub(crate) fn zip_with(entries: &[TestEntry<'_>], zip64_end: bool) -> Vec<u8> {
        let le16 = |v: u16| v.to_le_bytes().to_vec();
        let le32 = |v: u32| v.to_le_bytes().to_vec();
        let mut out = Vec::new();
        let mut central = Vec::new();
        for e in entries {
            let payload = if e.deflate {
                miniz_oxide::deflate::compress_to_vec(e.data, 6)
            } else {
                e.data.to_vec()
            };
            let method = if e.deflate { 8 } else { 0 };
            let crc = crc32fast::hash(e.data);
            let offset = out.len() as u32;
            // Local header: sizes left as ZIP64 placeholders with an extra field.
            let local_extra = [le16(1), le16(16), vec![0xAA; 16]].concat();
            out.extend(
                [
                    le32(LOCAL_SIG),
                    le16(45),
                    le16(0),
                    le16(method),
                    le32(0),
                    le32(crc),
                    le32(u32::MAX),
                    le32(u32::MAX),
                    le16(e.name.len() as u16),
                    le16(local_extra.len() as u16),
                ]
                .concat(),
            );
            out.extend_from_slice(e.name.as_bytes());
            out.extend(&local_extra);
            out.extend(&payload);
            let (csize, usize_, off, extra) = if e.zip64 {
                let extra = [
                    le16(1),
                    le16(24),
                    (e.data.len() as u64).to_le_bytes().to_vec(),
                    (payload.len() as u64).to_le_bytes().to_vec(),
                    u64::from(offset).to_le_bytes().to_vec(),
                ]
                .concat();
                (u32::MAX, u32::MAX, u32::MAX, extra)
            } else {
                // Some other extra field first, which the reader must skip.
                let extra = [le16(0x5455), le16(5), vec![1, 2, 3, 4, 5]].concat();
                (payload.len() as u32, e.data.len() as u32, offset, extra)
            };
            central.extend(
                [
                    le32(CENTRAL_SIG),
                    le16(45),
                    le16(45),
                    le16(0),
                    le16(method),
                    le32(0),
                    le32(crc),
                    le32(csize),
                    le32(usize_),
                    le16(e.name.len() as u16),
                    le16(extra.len() as u16),
                    le16(0),
                    le16(0),
                    le16(0),
                    le32(0),
                    le32(off),
                ]
                .concat(),
            );
            central.extend_from_slice(e.name.as_bytes());
            central.extend(&extra);
        }
        let cd_offset = out.len();
        out.extend(&central);
        let n = entries.len();
        if zip64_end {
            let end64 = out.len() as u64;
            out.extend(le32(ZIP64_END_SIG));
            out.extend(44u64.to_le_bytes());
            out.extend([le16(45), le16(45), le32(0), le32(0)].concat());
            for v in [n as u64, n as u64, central.len() as u64, cd_offset as u64] {
                out.extend(v.to_le_bytes());
            }
            out.extend([le32(ZIP64_LOCATOR_SIG), le32(0)].concat());
            out.extend(end64.to_le_bytes());
            out.extend(le32(1));
        }
        let comment = b"made by a test";
        let (count, offset) = if zip64_end {
            (u16::MAX, u32::MAX)
        } else {
            (n as u16, cd_offset as u32)
        };
        out.extend(
            [
                le32(END_SIG),
                le16(0),
                le16(0),
                le16(count),
                le16(count),
                le32(central.len() as u32),
                le32(offset),
                le16(comment.len() as u16),
            ]
            .concat(),
        );
        out.extend_from_slice(comment);
        out
    }

    #[test]
    fn stored_archives_round_trip() {
        let a: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        let entries: Vec<(&str, &[u8])> = vec![("a.npy", &a), ("empty.npy", &[]), ("b", b"xyz")];
        let bytes = write_zip(&entries).unwrap();
        let back = read_zip(&bytes).unwrap();
        assert_eq!(back.len(), 3);
        for ((name, data), (n2, d2)) in entries.iter().zip(&back) {
            assert_eq!((*name, *data), (n2.as_str(), d2.as_slice()));
        }
        // Deterministic bytes.
        assert_eq!(write_zip(&entries).unwrap(), bytes);
        assert!(read_zip(&write_zip(&[]).unwrap()).unwrap().is_empty());
    }

    #[test]
    fn deflate_and_zip64_entries_are_read() {
        let text = b"the quick brown fox jumps over the lazy dog ".repeat(50);
        let small = b"tiny".to_vec();
        for zip64_end in [false, true] {
            let bytes = zip_with(
                &[
                    TestEntry {
                        name: "x.npy",
                        data: &text,
                        deflate: true,
                        zip64: false,
                    },
                    TestEntry {
                        name: "y.npy",
                        data: &small,
                        deflate: false,
                        zip64: true,
                    },
                    TestEntry {
                        name: "z.npy",
                        data: &text,
                        deflate: true,
                        zip64: true,
                    },
                ],
                zip64_end,
            );
            // The DEFLATE entries really are compressed.
            assert!(bytes.len() < text.len());
            let back = read_zip(&bytes).unwrap();
            assert_eq!(back[0], ("x.npy".to_owned(), text.clone()));
            assert_eq!(back[1], ("y.npy".to_owned(), small.clone()));
            assert_eq!(back[2].1, text);
        }
    }

    #[test]
    fn corrupt_archives_are_errors() {
        let data = b"0123456789".repeat(20);
        let bytes = zip_with(
            &[TestEntry {
                name: "x.npy",
                data: &data,
                deflate: true,
                zip64: false,
            }],
            false,
        );
        let err = read_zip(b"not a zip").unwrap_err();
        assert!(err.expected.contains("end-of-central-directory"), "{err}");
        // Every truncation is an error, never a panic.
        for cut in 0..bytes.len() {
            assert!(read_zip(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        // A flipped bit in the compressed data: an inflate or CRC error.
        let data_at = 30 + 5 + 20 + 3;
        let mut bad = bytes.clone();
        bad[data_at] ^= 0x10;
        let err = read_zip(&bad).unwrap_err();
        assert!(err.expected.contains("x.npy"), "{err}");
        // An unknown method.
        let mut bad = bytes.clone();
        let cd = bad
            .windows(4)
            .position(|w| w == CENTRAL_SIG.to_le_bytes())
            .unwrap();
        bad[cd + 10] = 12;
        let err = read_zip(&bad).unwrap_err();
        assert_eq!(
            err.to_string(),
            "expected entry \"x.npy\" STORED (0) or DEFLATE (8), got compression method 12"
        );
        // Encrypted.
        let mut bad = bytes.clone();
        bad[cd + 8] = 1;
        assert!(read_zip(&bad).unwrap_err().found.contains("encrypted"));
        // A header that declares more than DEFLATE can expand to (3.2 GB from a few bytes) is
        // refused before anything is inflated.
        let mut bad = bytes.clone();
        bad[cd + 24..cd + 28].copy_from_slice(&3_200_000_000u32.to_le_bytes());
        let err = read_zip(&bad).unwrap_err();
        assert!(
            err.found.contains("3200000000 bytes declared") && err.expected.contains("x.npy"),
            "{err}"
        );
    }

    #[test]
    fn archives_larger_than_the_limit_are_refused_before_inflating() {
        let data = vec![7u8; 1000];
        let entry = |name| TestEntry {
            name,
            data: &data,
            deflate: true,
            zip64: false,
        };
        let two = zip_with(&[entry("a.npy"), entry("b.npy")], false);
        assert_eq!(read_zip_with_limit(&two, 2000).unwrap().len(), 2);
        let err = read_zip_with_limit(&two, 1999).unwrap_err();
        assert_eq!(
            err.to_string(),
            "expected an archive of at most 1999 bytes uncompressed, got 2000 bytes up to entry \
             \"b.npy\""
        );
    }
}
