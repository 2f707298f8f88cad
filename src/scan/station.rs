//! The station as the scan runner sees it: something that can (re)open the instrument and
//! the y axis, and say whether their ports are there. Device errors are reduced to a
//! [`Fault`] (which device, how to react, the NG code, the message) so the runner decides
//! uniformly without knowing the drivers.
//!
//! [`SerialStation`] is the real one: the SJ-210 client and the motion policy over ports
//! opened by [`crate::transport`]. Tests substitute their own.
//!
//! Layer 3 (session): depends on [`crate::devices`], the driver settings and
//! [`crate::transport`] (through the drivers' constructors).

use crate::devices::{FaultClass, Instrument, YAxis};
use crate::profile::Conditions;
use crate::sj210::client::Sj210Client;
use crate::sj210::models::ModelTable;
use crate::sj210::sampling::pitch_from_lambda_s;
use crate::sj210::settings::InstrumentSettings;
use crate::stage::{AnyYAxis, ScanDirection, StageError, StageSettings};
use std::path::Path;
use tokio_serial::SerialStream;

pub use crate::devices::{Device, Fault};

/// Opens the devices of a station.
#[allow(async_fn_in_trait)]
pub trait Station {
    /// The profiler type (sent to a blocking thread to be closed).
    type Instrument: Instrument + Send + 'static;
    /// The y axis type (sent to a blocking thread to be closed).
    type Stage: YAxis + Send + 'static;
    /// Opens the instrument's link (the conversation starts with `probe`).
    async fn open_instrument(&mut self) -> Result<Self::Instrument, Fault>;
    /// Opens the stage's link for a scan in `direction` (the conversation starts with
    /// `connect`).
    async fn open_stage(&mut self, direction: ScanDirection) -> Result<Self::Stage, Fault>;
    /// Whether the instrument's port is there (without opening it).
    fn instrument_present(&self) -> bool;
    /// Whether the stage's port is there (without opening it).
    fn stage_present(&self) -> bool;
    /// The configured ports of the instrument and the stage, when they are device paths
    /// (to name them when they look swapped).
    fn ports(&self) -> Option<(String, String)> {
        None
    }
    /// The x pitch in µm the instrument's profile will have under `conditions`, when it
    /// can be known before a trace (for the pre-flight estimate).
    fn expected_pitch_um(&self, conditions: &Conditions) -> Option<f64>;
    /// Sets up the next scan: with the settings that shape its lines as `recorded` (the
    /// configuration frozen in a resumed scan's start record) holds them, or with the
    /// station's configured ones (`None`: a new scan). Returns, for people, how the kept
    /// settings differ from the configuration (or why the record's could not be used).
    fn freeze(&mut self, recorded: Option<&serde_json::Value>) -> Vec<String> {
        let _ = recorded;
        Vec::new()
    }
}

/// Whether both devices answer properly: the instrument probed, the stage connected and
/// its state read (nothing moves); each closed again. The first fault, when one does not.
pub async fn devices_answer<S: Station>(
    station: &mut S,
    direction: ScanDirection,
) -> Result<(), Fault> {
    let mut instrument = station.open_instrument().await?;
    let probed = instrument.probe().await;
    closed(close_aside(Some(instrument))).await;
    probed.map_err(|e| Fault::of(Device::Instrument, &e))?;
    let mut stage = station.open_stage(direction).await?;
    let connected = stage.connect().await;
    closed(close_aside(Some(stage))).await;
    connected.map_err(|e| Fault::of(Device::Stage, &e))?;
    Ok(())
}

/// Drops a device on a blocking thread: closing a port whose link takes no bytes waits for
/// the driver's closing wait (30 s by default), which must not hold a runtime thread. The
/// port is opened exclusively: await the handle before opening it again.
pub fn close_aside<T: Send + 'static>(device: Option<T>) -> Option<tokio::task::JoinHandle<()>> {
    device.map(|d| tokio::task::spawn_blocking(move || drop(d)))
}

async fn closed(handle: Option<tokio::task::JoinHandle<()>>) {
    if let Some(h) = handle {
        let _ = h.await;
    }
}

/// The real station: serial ports from the configuration.
#[derive(Debug, Clone)]
pub struct SerialStation {
    /// `[instrument]`.
    pub instrument: InstrumentSettings,
    /// The model table with overrides merged (from [`InstrumentSettings::validate`]).
    pub table: ModelTable,
    /// `[stage]`.
    pub stage: StageSettings,
    /// `[instrument]` and `[stage]` as configured, restored for a new scan.
    configured: (InstrumentSettings, StageSettings),
}

impl SerialStation {
    /// Builds the station from the settings (validated again here).
    pub fn new(instrument: InstrumentSettings, stage: StageSettings) -> Result<Self, String> {
        let table = instrument.validate().map_err(|e| e.to_string())?;
        Ok(SerialStation {
            configured: (instrument.clone(), stage.clone()),
            instrument,
            table,
            stage,
        })
    }
}

impl Station for SerialStation {
    type Instrument = Sj210Client<SerialStream>;
    type Stage = AnyYAxis<SerialStream>;

    async fn open_instrument(&mut self) -> Result<Self::Instrument, Fault> {
        let port = crate::transport::open(&self.instrument.serial()).map_err(|e| Fault {
            device: Device::Instrument,
            class: if e.is_absent() {
                FaultClass::Absent
            } else {
                FaultClass::Fatal
            },
            ng_code: None,
            message: e.to_string(),
        })?;
        // Replies to commands of an earlier process (killed mid-conversation) may still sit
        // in the input buffer; they must not be taken as answers to this one's.
        if let Err(e) = tokio_serial::SerialPort::clear(&port, tokio_serial::ClearBuffer::Input) {
            tracing::debug!("cannot clear the instrument's input buffer: {e}");
        }
        Ok(Sj210Client::new(
            port,
            self.table.clone(),
            self.instrument.client_options(),
        ))
    }

    async fn open_stage(&mut self, direction: ScanDirection) -> Result<Self::Stage, Fault> {
        let mut axis = open_stage(&self.stage).map_err(|e| Fault::of(Device::Stage, &e))?;
        axis.set_scan_direction(direction);
        Ok(axis)
    }

    fn instrument_present(&self) -> bool {
        Path::new(&self.instrument.port).exists()
    }

    fn stage_present(&self) -> bool {
        Path::new(&self.stage.port).exists()
    }

    fn ports(&self) -> Option<(String, String)> {
        Some((self.instrument.port.clone(), self.stage.port.clone()))
    }

    fn expected_pitch_um(&self, c: &Conditions) -> Option<f64> {
        self.instrument
            .pitch_x_um
            .or_else(|| c.lambda_s_um.and_then(pitch_from_lambda_s))
    }

    fn freeze(&mut self, recorded: Option<&serde_json::Value>) -> Vec<String> {
        let (instrument, stage) = self.configured.clone();
        let (instrument, stage, said) = match recorded {
            None => (instrument, stage, Vec::new()),
            Some(r) => match super::frozen::frozen(&instrument, &stage, r) {
                Ok(kept) => kept,
                Err(e) => (
                    instrument,
                    stage,
                    vec![format!(
                        "the scan's own settings are not used: {e}; the configuration's are"
                    )],
                ),
            },
        };
        // The model table depends on nothing frozen here; validated once in `new`.
        self.instrument = instrument;
        self.stage = stage;
        said
    }
}

/// Validates the `[stage]` settings, then opens the port (via [`crate::transport::open`]) and
/// builds the selected driver and the motion policy over it; the axis still needs
/// [`YAxis::connect`].
pub fn open_stage(settings: &StageSettings) -> Result<AnyYAxis<SerialStream>, StageError> {
    settings.validate()?;
    let io = crate::transport::open(&settings.serial())?;
    AnyYAxis::new(settings, io)
}
