//! Reading the input files (scenarios, attacks, campaigns, deployments) within the size limit,
//! and naming what a path is when it is not a regular file.

use std::path::Path;

use crate::limits::MAX_FILE_BYTES;

/// Reads a TOML file of at most [`MAX_FILE_BYTES`]: a scenario, an attack, a campaign or a
/// deployment file. Only a regular file is read (a device, a pipe or a directory is refused
/// without reading from it), and never more than the limit whatever size the file claims
/// (files in `/proc` claim 0 bytes; a file may grow while read). The file is opened without
/// blocking: a named pipe nobody writes to is refused at once, not waited on.
pub fn read_limited(path: &Path) -> Result<String, String> {
    use std::io::Read;
    let cannot = |e: std::io::Error| format!("cannot read {}: {e}", path.display());
    let file = open_to_read(path).map_err(cannot)?;
    let meta = file.metadata().map_err(cannot)?;
    if !meta.is_file() {
        return Err(format!(
            "{} is not a regular file ({}): scenario, attack, campaign and deployment files must be regular files of at most {MAX_FILE_BYTES} bytes",
            path.display(),
            file_kind(meta.file_type()),
        ));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(format!(
            "{} is {} bytes, larger than the {MAX_FILE_BYTES} byte limit",
            path.display(),
            meta.len()
        ));
    }
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(cannot)?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(format!(
            "{} holds more than the {MAX_FILE_BYTES} byte limit",
            path.display()
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        format!(
            "cannot read {}: not UTF-8 text (byte offset {})",
            path.display(),
            e.utf8_error().valid_up_to()
        )
    })
}

/// Opens `path` for reading without waiting on it: a named pipe that no program writes to
/// opens at once (a plain open blocks until a writer comes, deaf to the launcher's stop), so
/// that the caller can look at what it opened and refuse it. Nothing changes for a regular
/// file.
pub fn open_to_read(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt as _;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(rustix::fs::OFlags::NONBLOCK.bits() as i32)
        .open(path)
}

/// Why a name read from a file (a scenario's, an attack profile's, a campaign's) cannot be
/// shown, or `None`: a control character (NUL, ESC, …) would end up in figure titles (an SVG
/// cannot hold one), table cells and the terminal (where ESC starts a command).
pub fn unprintable(name: &str) -> Option<String> {
    let (at, c) = name.char_indices().find(|(_, c)| c.is_control())?;
    Some(format!(
        "holds the control character U+{:04X} at byte {at}: names are printed in titles, tables \
         and on the terminal, and may hold no control character",
        u32::from(c)
    ))
}

/// What a file that is not a regular one is, for messages.
pub fn file_kind(t: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a named pipe"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_file() {
        "a regular file"
    } else {
        "a special file"
    }
}
