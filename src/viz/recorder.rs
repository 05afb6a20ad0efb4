//! The open recording: its sinks (a file, a spawned viewer, a running viewer), its default
//! layout, and the JPEG compression of the camera images it holds.

use super::{Recording, RecordingRequest, Sink, VizError, IMAGE_JPEG_QUALITY};
use std::path::Path;

/// An open recording.
pub struct Recorder {
    rec: rerun::RecordingStream,
    /// The `.rrd` files being written, renamed into place when the recording is finished.
    files: Vec<crate::io::PartialFile>,
}

impl Recorder {
    /// Opens the recording `request` asks for, with the default layout of `kind`; `None` when
    /// it asks for none. `default_file` is written unless the request names other sinks.
    pub fn open(
        request: &RecordingRequest,
        kind: Recording,
        default_file: &Path,
    ) -> Result<Option<Recorder>, VizError> {
        let sinks = request.sinks(default_file);
        if sinks.is_empty() {
            return Ok(None);
        }
        Self::new(kind.application(), &sinks).map(Some)
    }

    /// Opens a recording to the sinks; its layout is sent with what it logs.
    fn new(application: &'static str, sinks: &[Sink]) -> Result<Self, VizError> {
        let mut boxed: Vec<Box<dyn rerun::sink::LogSink>> = Vec::new();
        let mut files = Vec::new();
        for sink in sinks {
            match sink {
                Sink::Save(path) => {
                    let bad = |message: String| VizError::Url {
                        url: path.display().to_string(),
                        message,
                    };
                    let file =
                        crate::io::PartialFile::create(path).map_err(|e| bad(e.to_string()))?;
                    boxed.push(Box::new(
                        rerun::sink::FileSink::new(file.path()).map_err(|e| bad(e.to_string()))?,
                    ));
                    files.push(file);
                }
                Sink::Spawn => {
                    rerun::spawn(&rerun::SpawnOptions::default())
                        .map_err(|e| VizError::Spawn(e.to_string()))?;
                    boxed.push(Box::new(rerun::sink::GrpcSink::new(
                        rerun::DEFAULT_CONNECT_URL.parse().map_err(
                            |e: rerun::external::re_uri::Error| VizError::Url {
                                url: rerun::DEFAULT_CONNECT_URL.into(),
                                message: e.to_string(),
                            },
                        )?,
                    )));
                }
                Sink::Connect(url) => boxed.push(Box::new(rerun::sink::GrpcSink::new(
                    url.parse()
                        .map_err(|e: rerun::external::re_uri::Error| VizError::Url {
                            url: url.clone(),
                            message: e.to_string(),
                        })?,
                ))),
            }
        }
        let rec = rerun::RecordingStreamBuilder::new(application).set_sinks(boxed)?;
        Ok(Self { rec, files })
    }

    /// Flushes everything to the sinks and moves the `.rrd` files into place (until then they
    /// are hidden partial files, removed if the program stops first).
    pub fn finish(self) -> Result<(), VizError> {
        self.rec.flush_blocking().map_err(|e| VizError::Flush {
            message: e.to_string(),
        })?;
        // The sinks closed (the files complete) before they move.
        self.rec.disconnect();
        for file in self.files {
            file.commit().map_err(|e| VizError::Flush {
                message: e.to_string(),
            })?;
        }
        Ok(())
    }

    /// The stream, for the recordings' `log_*` methods.
    pub(super) fn stream(&self) -> &rerun::RecordingStream {
        &self.rec
    }
}

/// A stereo pair compressed for the recording (compressing is most of a recording's cost, so the
/// survey does it alongside its single-threaded stages).
pub fn jpeg_pair(left: &image::GrayImage, right: &image::GrayImage) -> Option<(Vec<u8>, Vec<u8>)> {
    Some((jpeg(left).ok()?, jpeg(right).ok()?))
}

/// One image compressed for the recording.
pub fn jpeg_image(img: &image::GrayImage) -> Option<Vec<u8>> {
    jpeg(img).ok()
}

/// One image as JPEG at [`IMAGE_JPEG_QUALITY`].
pub(super) fn jpeg(img: &image::GrayImage) -> Result<Vec<u8>, VizError> {
    let mut bytes = Vec::new();
    let (Ok(w), Ok(h)) = (u16::try_from(img.width()), u16::try_from(img.height())) else {
        return Err(VizError::Jpeg(format!(
            "a {}x{} image is too large for JPEG",
            img.width(),
            img.height()
        )));
    };
    jpeg_encoder::Encoder::new(&mut bytes, IMAGE_JPEG_QUALITY)
        .encode(img.as_raw(), w, h, jpeg_encoder::ColorType::Luma)
        .map_err(|e| VizError::Jpeg(e.to_string()))?;
    Ok(bytes)
}
