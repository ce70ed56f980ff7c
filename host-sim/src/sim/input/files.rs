//! Every file the simulator reads from the user or writes for them goes through here:
//!
//! - [`read_text`], [`read_bytes`]: input read with a size cap, so a symlink to `/dev/zero` or
//!   a file that never ends is refused with its name and the limit instead of eating memory;
//! - [`write_file`], [`write_with`], [`PendingFile`] (for the plots): output written to a
//!   temporary file next to its target and renamed over it when complete, so a full disk leaves
//!   no truncated file, and every error names the file;
//! - [`OutDir::claim`]: an output folder created and locked for one run, so two runs writing
//!   the same folder at once cannot mix their files;
//! - [`report_stdout_errors`]: the printed tables and text, when the standard output cannot
//!   take them (`> file` on a full disk), an error naming where it goes.

use anyhow::{anyhow, bail, Context, Result};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Largest text input (scenario, vehicle and mapping files), bytes.
pub const TEXT_LIMIT: u64 = 4 << 20;
/// Largest data input (a measured log, a firmware image, a file hashed into a provenance),
/// bytes: an hour's log at 1 kHz with a dozen columns is about half of it.
pub const DATA_LIMIT: u64 = 1 << 30;

fn mib(bytes: u64) -> String {
    format!("{} MiB", bytes >> 20)
}

/// The bytes of `path`, refused when it holds more than `limit`.
pub fn read_bytes(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let too_large = || {
        anyhow!(
            "{} is larger than the limit of {} ({limit} bytes) for this input",
            path.display(),
            mib(limit)
        )
    };
    let f = File::open(path).with_context(|| format!("reading {}", path.display()))?;
    // A regular file's length refuses it before a byte is read; a device or a pipe has none.
    if f.metadata().is_ok_and(|m| m.is_file() && m.len() > limit) {
        return Err(too_large());
    }
    let mut bytes = Vec::new();
    // One byte past the limit tells a file at the limit from a larger one.
    f.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading {}", path.display()))?;
    if bytes.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(bytes)
}

/// The text of `path` (UTF-8), refused when it holds more than `limit` bytes.
pub fn read_text(path: &Path, limit: u64) -> Result<String> {
    String::from_utf8(read_bytes(path, limit)?)
        .with_context(|| format!("reading {}: not UTF-8 text", path.display()))
}

/// Writes `bytes` to `path` as [`write_with`] does.
pub fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_with(path, |w| w.write_all(bytes.as_ref()))
}

/// Writes `path` through `fill`: into a temporary file in the same folder, flushed to the disk
/// and renamed over `path` only when all of it was written, so a failure (a full disk) leaves
/// `path` as it was and no partial file. A path that exists and is no regular file (a device,
/// a pipe: `/dev/stdout`) is written in place. Errors name `path`.
pub fn write_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let in_place = std::fs::metadata(path).is_ok_and(|m| !m.is_file());
    let target = if in_place {
        path.to_path_buf()
    } else {
        temp_sibling(path)
    };
    let written = (|| -> std::io::Result<()> {
        let f = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&target)?;
        let mut w = BufWriter::new(f);
        fill(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        if !in_place {
            f.sync_all()?;
            std::fs::rename(&target, path)?;
        }
        Ok(())
    })();
    if let Err(e) = written {
        if !in_place {
            let _ = std::fs::remove_file(&target);
        }
        return Err(e).with_context(|| format!("writing {}", path.display()));
    }
    Ok(())
}

/// `.NAME.PID.tmp.EXT` next to `path`: hidden, one per process, and the extension kept for
/// writers that choose the format by it (the plot backend).
fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or("out".into(), |n| n.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!(".{name}.{}.tmp{ext}", std::process::id()))
}

/// A file that a writer opens itself (the plot backend) written under a temporary name next to
/// its target ([`PendingFile::tmp`]) and renamed over it by [`PendingFile::commit`] when
/// complete; dropped without a commit (an error on the way), the temporary file is removed.
#[derive(Debug)]
pub struct PendingFile {
    path: PathBuf,
    tmp: PathBuf,
}

impl PendingFile {
    /// The file `path`, to be written at [`PendingFile::tmp`] first.
    pub fn new(path: &Path) -> Self {
        PendingFile {
            path: path.to_path_buf(),
            tmp: temp_sibling(path),
        }
    }

    /// Where the writer writes.
    pub fn tmp(&self) -> &Path {
        &self.tmp
    }

    /// Moves the written file into place once `written` (the writer's result) is `Ok`; errors
    /// name the target.
    pub fn commit<E>(&self, written: std::result::Result<(), E>) -> Result<()>
    where
        E: std::error::Error + Send + Sync + 'static,
    {
        let done = written.map_err(anyhow::Error::new).and_then(|()| {
            File::open(&self.tmp)?.sync_all()?;
            std::fs::rename(&self.tmp, &self.path)?;
            Ok(())
        });
        if done.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        done.with_context(|| format!("writing {}", self.path.display()))
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        // Renamed already after a commit; otherwise the partial file goes.
        let _ = std::fs::remove_file(&self.tmp);
    }
}

/// Makes a failed write to the standard output (a full disk under `> file`) an error that
/// names where the output goes, with exit status 1, instead of the panic of `println!`; a
/// closed pipe ends the run quietly with status 0. Installed once at start-up.
pub fn report_stdout_errors() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let why = info
            .payload_as_str()
            .and_then(|m| m.strip_prefix("failed printing to stdout: "));
        match why {
            // The reader stopped reading (`| head`): what it wanted arrived; quiet, as a
            // Unix tool dying of SIGPIPE.
            Some(why) if why.contains("Broken pipe") => std::process::exit(0),
            Some(why) => {
                let _ = writeln!(
                    std::io::stderr(),
                    "Error: writing the standard output{}: {why}",
                    stdout_target()
                );
                std::process::exit(1);
            }
            None => default(info),
        }
    }));
}

/// " (FILE)" for the file the standard output goes to where the system says (Linux), else "".
fn stdout_target() -> String {
    std::fs::read_link("/proc/self/fd/1").map_or(String::new(), |p| format!(" ({})", p.display()))
}

/// The lock file of an output folder, held while a run writes it.
pub const LOCK_FILE: &str = ".shimmy-sim.lock";

/// An output folder claimed by this run: created if missing and locked (an advisory lock on
/// [`LOCK_FILE`] in it) until this value is dropped. The operating system releases the lock
/// when the process ends however it ends, so a crashed run never blocks the next one.
#[derive(Debug)]
pub struct OutDir {
    path: PathBuf,
    _lock: File,
}

impl OutDir {
    /// Creates `path` (and its parents) and locks it; fails naming the folder when another run
    /// holds it.
    pub fn claim(path: &Path) -> Result<OutDir> {
        std::fs::create_dir_all(path).with_context(|| format!("creating {}", path.display()))?;
        let lock_path = path.join(LOCK_FILE);
        let lock = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)
            .with_context(|| format!("creating {}", lock_path.display()))?;
        match lock.try_lock() {
            Ok(()) => Ok(OutDir {
                path: path.to_path_buf(),
                _lock: lock,
            }),
            Err(std::fs::TryLockError::WouldBlock) => bail!(
                "output folder {} is in use by another shimmy-sim run (it holds {}); wait for \
                 it to finish or choose another --out",
                path.display(),
                LOCK_FILE
            ),
            Err(std::fs::TryLockError::Error(e)) => {
                Err(e).with_context(|| format!("locking {}", lock_path.display()))
            }
        }
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("shimmy-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_input_over_the_limit_is_refused_naming_it_and_the_limit() {
        let d = temp_dir("limit");
        let f = d.join("big.toml");
        std::fs::write(&f, vec![b'#'; 1000]).unwrap();
        assert_eq!(read_bytes(&f, 1000).unwrap().len(), 1000);
        let e = format!("{:#}", read_text(&f, 999).unwrap_err());
        assert!(
            e.contains("big.toml") && e.contains("limit") && e.contains("999 bytes"),
            "{e}"
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn an_endless_input_is_refused_not_read_to_the_end() {
        let d = temp_dir("endless");
        let link = d.join("zero.toml");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let e = format!("{:#}", read_text(&link, TEXT_LIMIT).unwrap_err());
        assert!(e.contains("zero.toml") && e.contains("4 MiB"), "{e}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_to_a_full_disk_fails_naming_the_file() {
        let e = format!(
            "{:#}",
            write_file(Path::new("/dev/full"), "x\n").unwrap_err()
        );
        assert!(e.contains("writing /dev/full"), "{e}");
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary_one() {
        let d = temp_dir("atomic");
        let f = d.join("a.csv");
        write_file(&f, "old\n").unwrap();
        let e = write_with(&f, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(format!("{e:#}").contains("a.csv"), "{e:#}");
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "old\n");
        let names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["a.csv"]);
    }

    #[test]
    fn a_pending_file_is_moved_into_place_only_when_written() {
        let d = temp_dir("pending");
        let f = d.join("p.png");
        let p = PendingFile::new(&f);
        std::fs::write(p.tmp(), "half").unwrap();
        let e = p
            .commit(Err(std::io::Error::other("disk full")))
            .unwrap_err();
        assert!(format!("{e:#}").contains("writing") && format!("{e:#}").contains("p.png"));
        assert!(
            std::fs::read_dir(&d).unwrap().next().is_none(),
            "nothing left"
        );
        let p = PendingFile::new(&f);
        assert!(
            p.tmp().extension().is_some_and(|e| e == "png"),
            "format by extension"
        );
        std::fs::write(p.tmp(), "whole").unwrap();
        p.commit(Ok::<(), std::io::Error>(())).unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "whole");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
    }

    #[test]
    fn a_claimed_folder_is_refused_to_a_second_claim_until_released() {
        let d = temp_dir("claim").join("out");
        let first = OutDir::claim(&d).unwrap();
        let e = format!("{:#}", OutDir::claim(&d).unwrap_err());
        assert!(
            e.contains(&d.display().to_string()) && e.contains("in use"),
            "{e}"
        );
        drop(first);
        OutDir::claim(&d).expect("free again");
    }
}
