//! Reading a file a user names, at most so many bytes: a device that never
//! ends (`/dev/zero`, a FIFO) or a file far larger than its kind ever is gets
//! refused at the bound instead of being read until memory runs out.

use std::io::Read;
use std::path::Path;

/// The most bytes of a manifest (the committed ones are a few kilobytes).
pub const MANIFEST_BYTES: u64 = 16 << 20;
/// The most bytes of a robot description (the largest URDF of the
/// example-robot-data collection is under 1 MB; meshes are not read).
pub const DESCRIPTION_BYTES: u64 = 64 << 20;

/// The bytes of `path`, if there are at most `limit` of them; otherwise an
/// error of kind `FileTooLarge` naming `what` the file should be and the
/// bound.
pub fn read(path: &Path, limit: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!(
                "more than {} MiB, far more than {what} holds: refused",
                limit >> 20
            ),
        ));
    }
    Ok(bytes)
}

/// [`read`] as UTF-8 text.
pub fn read_to_string(path: &Path, limit: u64, what: &str) -> std::io::Result<String> {
    String::from_utf8(read(path, limit, what)?).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text, as {what} is"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_within_the_bound_reads_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, vec![7u8; 1 << 20]).unwrap();
        assert_eq!(read(&path, 1 << 20, "a test").unwrap().len(), 1 << 20);
    }

    #[test]
    fn an_endless_device_is_refused_at_the_bound() {
        let error = read(Path::new("/dev/zero"), 2 << 20, "a manifest").unwrap_err();
        assert_eq!(error.kind(), std::io::ErrorKind::FileTooLarge);
        assert_eq!(
            error.to_string(),
            "more than 2 MiB, far more than a manifest holds: refused"
        );
    }
}
