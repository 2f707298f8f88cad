//! The instrument's plain reads: status, battery, conditions, parameter count and the
//! results of the last trace, each reply read by the pure parsers in
//! [`crate::sj210::replies`].
//!
//! Layer 2: part of [`super::Sj210Client`].

use super::Sj210Client;
use crate::devices::Battery;
use crate::profile::{Conditions, InstrumentResult};
use crate::sj210::error::Sj210Error;
use crate::sj210::replies::{battery_from_code, parse_code, parse_param_count, parse_result};
use tokio::io::{AsyncRead, AsyncWrite};

impl<S: AsyncRead + AsyncWrite + Unpin> Sj210Client<S> {
    pub(super) async fn read_code(
        &mut self,
        command: String,
        expected: &'static str,
    ) -> Result<u16, Sj210Error> {
        let payload = self.command(&command, true).await?;
        parse_code(&payload).ok_or(Sj210Error::UnexpectedReply {
            command,
            payload,
            expected,
        })
    }

    /// Operating status (`RDSTU00`).
    pub async fn status(&mut self) -> Result<u16, Sj210Error> {
        let c = self.table.commands.status.plain();
        self.read_code(c, "a 3-digit status").await
    }

    /// Battery state (`RDSTU01`).
    pub async fn battery(&mut self) -> Result<Battery, Sj210Error> {
        let c = self.table.commands.battery.plain();
        let code = self.read_code(c, "a 3-digit battery code").await?;
        let b = battery_from_code(code);
        self.battery = Some(b);
        Ok(b)
    }

    /// Measurement conditions (`RDCON`).
    pub async fn conditions(&mut self) -> Result<Conditions, Sj210Error> {
        let c = self.table.commands.conditions.plain();
        let payload = self.command(&c, true).await?;
        let cond = match self.table.parse_conditions(&payload) {
            Ok(cond) => cond,
            // Read fine before on this link: this payload is a stray or late reply taken for
            // the answer, not a layout the configured model does not know.
            Err(_) if self.conditions.is_some() => {
                return Err(Sj210Error::UnexpectedReply {
                    command: c,
                    payload,
                    expected: "a conditions record like the one read before on this link",
                })
            }
            Err(e) => return Err(e.into()),
        };
        self.conditions = Some(cond.clone());
        Ok(cond)
    }

    /// Number of customised parameters (`RDPAR`).
    pub async fn parameter_count(&mut self) -> Result<u32, Sj210Error> {
        self.parameter_count_with(true).await
    }

    /// [`Sj210Client::parameter_count`], retried on busy codes only when `retry` is true.
    async fn parameter_count_with(&mut self, retry: bool) -> Result<u32, Sj210Error> {
        let c = self.table.commands.param_count.plain();
        let payload = self.command(&c, retry).await?;
        parse_param_count(&payload).ok_or(Sj210Error::UnexpectedReply {
            command: c,
            payload,
            expected: "a 2-digit parameter count",
        })
    }

    /// Reads every result parameter the instrument reports: `RDPAR` (how many are
    /// customised), then the result command for 01..=n, each as printed
    /// ([`crate::sj210::replies::parse_result`]). A parameter answering a calculation error
    /// (NG102–199) is kept by its number with the code and no value, and warned about.
    pub async fn read_results(
        &mut self,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<InstrumentResult>, Sj210Error> {
        self.read_results_with(warnings, true).await
    }

    /// [`Sj210Client::read_results`]; with `retry` false a busy answer (`NG011`, `NG033`) is
    /// returned at once instead of retried, as while the drive returns it means "not during
    /// the return", not "not yet".
    pub(super) async fn read_results_with(
        &mut self,
        warnings: &mut Vec<String>,
        retry: bool,
    ) -> Result<Vec<InstrumentResult>, Sj210Error> {
        let n = self.parameter_count_with(retry).await?;
        let width = self.table.result_value_width;
        let mut out = Vec::with_capacity(n as usize);
        for aa in 1..=n {
            let cmd = self.table.commands.result.render(aa, 0, 0);
            match self.command(&cmd, retry).await {
                Ok(payload) => out.push(parse_result(&cmd, &payload, width)?),
                // Calculation errors of one parameter: record it without a value.
                Err(Sj210Error::Device { code, meaning, .. })
                    if (102..=199).contains(&code.code()) =>
                {
                    warnings.push(format!("parameter {aa:02}: {code} ({meaning})"));
                    out.push(InstrumentResult {
                        name: format!("#{aa:02}"),
                        value: None,
                        unit: String::new(),
                        printed: None,
                        ng_code: Some(code.code()),
                    });
                }
                Err(e) => return Err(e),
            }
        }
        Ok(out)
    }
}
