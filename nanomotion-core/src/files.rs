//! Reading text files through a bounded reader: graph files, included files,
//! data files and calibration tables all go through [`read_text_capped`], so a
//! device such as `/dev/zero` or a huge file is an error naming the size, never
//! an endless read. At the bottom of the core (no other module needed).

/// Read a UTF-8 text file of at most `max_bytes` bytes through a bounded reader
/// (so `/dev/zero` or a huge file is an error, not an endless read).
pub fn read_text_capped(path: &std::path::Path, max_bytes: u64) -> std::io::Result<String> {
    use std::io::Read as _;
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {} MiB; is it the right file?", max_bytes >> 20),
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text ({e})"),
        )
    })
}
