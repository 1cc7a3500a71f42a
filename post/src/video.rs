//! H.264 MP4s of a job's frames with FFmpeg, run as a program: the one `tessera install
//! ffmpeg` puts in the user's data folder, or the distribution's on the `PATH`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The FFmpeg release `tessera install ffmpeg` installs.
pub const FFMPEG_VERSION: &str = "9.0.2";

/// Why a video could not be made or read.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// No usable FFmpeg was found.
    #[error(
        "FFmpeg with libx264 is not installed (looked for {}, and `ffmpeg` on the PATH): run \
         `tessera install ffmpeg`{}",
        looked.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        reason.as_ref().map(|r| format!(" ({r})")).unwrap_or_default()
    )]
    NotInstalled {
        /// The programs looked for.
        looked: Vec<PathBuf>,
        /// Why the last one found could not be used.
        reason: Option<String>,
    },
    /// FFmpeg ran and failed.
    #[error("{program} {what}: {detail}")]
    Failed {
        /// The program.
        program: String,
        /// What it was doing.
        what: &'static str,
        /// Its exit status and the end of what it printed.
        detail: String,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// Nothing to encode, or a frame rate FFmpeg cannot take.
    #[error("{0}")]
    Invalid(String),
}

/// The folder `tessera install ffmpeg` installs into (the program in its `bin/`).
pub fn install_dir() -> PathBuf {
    crate::oidn::data_dir().join(format!("ffmpeg-{FFMPEG_VERSION}"))
}

/// What a video holds, as FFmpeg reads it back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoInfo {
    /// Frames in the stream.
    pub frames: u64,
    /// Frames per second.
    pub fps: f64,
    /// Width and height in pixels.
    pub size: (u32, u32),
    /// The stream's codec is H.264.
    pub h264: bool,
}

/// An FFmpeg program that can encode H.264.
#[derive(Clone, Debug)]
pub struct Ffmpeg {
    program: PathBuf,
}

impl Ffmpeg {
    /// Finds FFmpeg: `place` when given (the program, or a folder with it in `bin/` or at
    /// its top), else in [`install_dir`], else `ffmpeg` on the `PATH`. It must run and
    /// have the libx264 encoder.
    pub fn find(place: Option<&Path>) -> Result<Ffmpeg, VideoError> {
        let candidates: Vec<PathBuf> = match place {
            Some(p) if p.is_file() => vec![p.to_path_buf()],
            Some(dir) => vec![dir.join("bin/ffmpeg"), dir.join("ffmpeg")],
            None => vec![install_dir().join("bin/ffmpeg"), PathBuf::from("ffmpeg")],
        };
        let mut reason = None;
        for program in &candidates {
            let ffmpeg = Ffmpeg {
                program: program.clone(),
            };
            match ffmpeg.has_x264() {
                Ok(true) => return Ok(ffmpeg),
                Ok(false) => reason = Some(format!("{} has no libx264", program.display())),
                Err(_) => {}
            }
        }
        Err(VideoError::NotInstalled {
            looked: candidates,
            reason,
        })
    }

    /// The program.
    pub fn program(&self) -> &Path {
        &self.program
    }

    fn has_x264(&self) -> Result<bool, VideoError> {
        let out = self.run(
            &["-hide_banner", "-h", "encoder=libx264"],
            "listing encoders",
        )?;
        Ok(String::from_utf8_lossy(&out.stdout).contains("libx264"))
    }

    fn run(&self, args: &[&str], what: &'static str) -> Result<Output, VideoError> {
        let out = Command::new(&self.program)
            .args(args)
            .output()
            .map_err(|e| VideoError::Failed {
                program: self.program.display().to_string(),
                what,
                detail: e.to_string(),
            })?;
        if !out.status.success() {
            let stderr = String::from_utf8_lossy(&out.stderr);
            let tail: Vec<&str> = stderr.lines().rev().take(5).collect();
            return Err(VideoError::Failed {
                program: self.program.display().to_string(),
                what,
                detail: format!(
                    "{}: {}",
                    out.status,
                    tail.into_iter().rev().collect::<Vec<_>>().join(" / ")
                ),
            });
        }
        Ok(out)
    }

    /// Encodes `frames` (PNG files, in order) at `fps` into an H.264 MP4 at `out`, which
    /// browsers play: 4:2:0 (odd sizes padded by a pixel), BT.709 and tagged as sRGB,
    /// CRF 18 (visually lossless), the index at the front so playback starts before the
    /// whole file has arrived. Written beside `out` first, then renamed into place.
    pub fn encode(
        &self,
        frames: &[PathBuf],
        fps: f64,
        out: &Path,
        threads: u32,
    ) -> Result<(), VideoError> {
        if frames.is_empty() {
            return Err(VideoError::Invalid("no frames to encode".into()));
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(VideoError::Invalid(format!("{fps} frames per second")));
        }
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| VideoError::Io { path, source }
        };
        // FFmpeg reads an image sequence by a numbered pattern: the frames linked in order.
        let staging = tempfile::tempdir().map_err(io(Path::new("a temporary folder")))?;
        for (i, frame) in frames.iter().enumerate() {
            let link = staging.path().join(format!("{:06}.png", i + 1));
            let target = std::path::absolute(frame).map_err(io(frame))?;
            std::os::unix::fs::symlink(&target, &link).map_err(io(&link))?;
        }
        let partial = out.with_extension("partial.mp4");
        let pattern = staging.path().join("%06d.png");
        let (fps, threads) = (format!("{fps}"), threads.max(1).to_string());
        let args = [
            "-hide_banner",
            "-loglevel",
            "error",
            "-y",
            "-framerate",
            &fps,
            "-i",
            &pattern.to_string_lossy(),
            "-vf",
            "pad=ceil(iw/2)*2:ceil(ih/2)*2,scale=out_color_matrix=bt709:out_range=tv,format=yuv420p",
            "-c:v",
            "libx264",
            "-crf",
            "18",
            "-preset",
            "medium",
            "-colorspace",
            "bt709",
            "-color_primaries",
            "bt709",
            "-color_trc",
            "iec61966-2-1",
            "-color_range",
            "tv",
            "-movflags",
            "+faststart",
            "-threads",
            &threads,
            &partial.to_string_lossy(),
        ];
        let result = self.run(&args, "encoding the video");
        if let Err(e) = result {
            let _ = std::fs::remove_file(&partial);
            return Err(e);
        }
        std::fs::rename(&partial, out).map_err(io(out))
    }

    /// What the video at `path` holds: FFmpeg reads its stream through (copying, not
    /// decoding) and counts the frames.
    pub fn probe(&self, path: &Path) -> Result<VideoInfo, VideoError> {
        let out = self.run(
            &[
                "-hide_banner",
                "-i",
                &path.to_string_lossy(),
                "-map",
                "0:v:0",
                "-c",
                "copy",
                "-f",
                "null",
                "-",
            ],
            "reading the video",
        )?;
        let text = String::from_utf8_lossy(&out.stderr);
        parse_probe(&text).ok_or_else(|| VideoError::Failed {
            program: self.program.display().to_string(),
            what: "reading the video",
            detail: format!("no video stream in what it said: {text}"),
        })
    }

    /// Decodes frame `index` (from 0) of the video at `path` into a PNG at `png`.
    pub fn frame_png(&self, path: &Path, index: u64, png: &Path) -> Result<(), VideoError> {
        let select = format!("select=eq(n\\,{index})");
        self.run(
            &[
                "-hide_banner",
                "-loglevel",
                "error",
                "-y",
                "-i",
                &path.to_string_lossy(),
                "-vf",
                &select,
                "-frames:v",
                "1",
                &png.to_string_lossy(),
            ],
            "decoding a frame",
        )?;
        Ok(())
    }
}

/// Reads the stream line (`Stream #0:0...: Video: h264 ..., 256x192 ..., 24 fps`) and the
/// last progress count (`frame=   24`) of FFmpeg's report.
fn parse_probe(text: &str) -> Option<VideoInfo> {
    let stream = text
        .lines()
        .find(|l| l.contains("Stream #") && l.contains("Video:"))?;
    let h264 = stream.contains("Video: h264");
    let size = stream.split([',', ' ']).find_map(|w| {
        let (a, b) = w.split_once('x')?;
        Some((a.parse().ok()?, b.parse().ok()?))
    })?;
    let fps = stream
        .split(',')
        .find_map(|part| part.trim().strip_suffix(" fps")?.trim().parse().ok())?;
    let frames = text
        .rsplit("frame=")
        .next()
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())?;
    Some(VideoInfo {
        frames,
        fps,
        size,
        h264,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_gives_frames_rate_size_and_codec() {
        let text = "Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'demo.mp4':\n  Duration: 00:00:01.00\n  \
            Stream #0:0[0x1](und): Video: h264 (High) (avc1 / 0x31637661), yuv420p(tv, bt709/bt709/iec61966-2-1, progressive), 256x192, 30 kb/s, 24 fps, 24 tbr, 12288 tbn (default)\n\
            Output #0, null, to 'pipe:':\n\
            frame=   12 fps=0.0 q=-1.0 size=N/A\rframe=   24 fps=0.0 q=-1.0 Lsize=N/A time=00:00:00.95\n";
        assert_eq!(
            parse_probe(text),
            Some(VideoInfo {
                frames: 24,
                fps: 24.0,
                size: (256, 192),
                h264: true
            })
        );
        assert_eq!(parse_probe("no stream here"), None);
    }

    #[test]
    fn a_missing_program_says_what_to_run() {
        let dir = tempfile::tempdir().unwrap();
        let err = Ffmpeg::find(Some(dir.path())).unwrap_err();
        assert!(err.to_string().contains("tessera install ffmpeg"), "{err}");
    }
}
