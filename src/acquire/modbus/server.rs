//! A small Modbus server for simulated devices and tests (DESIGN.md §4, simulated
//! devices): a shared register bank that a producer task updates, served over TCP or RTU
//! (any serial stream, for example one end of a pty pair), with fault switches: slow
//! replies, an exception every k-th request, and stop/restart of the TCP listener.

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio_modbus::server::Service;
use tokio_modbus::server::tcp::{Server as TcpModbusServer, accept_tcp_connection};
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

/// Registers and coils of one device: every address of the 16-bit space.
#[derive(Debug, Clone)]
pub struct RegisterBank {
    pub holding: Vec<u16>,
    pub input: Vec<u16>,
    pub coils: Vec<bool>,
}

impl Default for RegisterBank {
    fn default() -> Self {
        RegisterBank { holding: vec![0; 0x1_0000], input: vec![0; 0x1_0000], coils: vec![false; 0x1_0000] }
    }
}

/// A bank shared by the server and the producer that updates it.
pub type SharedBank = Arc<Mutex<RegisterBank>>;

/// A new zeroed shared bank.
pub fn shared_bank() -> SharedBank {
    Arc::new(Mutex::new(RegisterBank::default()))
}

/// Lock a bank; a producer that panicked while holding it leaves plain data, still usable.
pub fn lock(bank: &SharedBank) -> MutexGuard<'_, RegisterBank> {
    bank.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Fault switches, changed at any time while serving; and what the server did.
#[derive(Debug, Default)]
pub struct Faults {
    /// Every reply is delayed by this many ms.
    pub delay_ms: AtomicU64,
    /// Every k-th request is answered with "server device busy" (0x06); 0 never.
    pub exception_every: AtomicU32,
    /// Requests received.
    pub requests: AtomicU64,
    /// Exceptions sent (faults and bad addresses).
    pub exceptions: AtomicU64,
}

impl Faults {
    pub fn set_delay(&self, delay: Duration) {
        self.delay_ms.store(delay.as_millis() as u64, Ordering::Relaxed);
    }

    pub fn set_exception_every(&self, k: u32) {
        self.exception_every.store(k, Ordering::Relaxed);
    }
}

/// The Modbus service over a bank. `unit`: answer only this unit id (and broadcasts,
/// silently) as an RTU slave does; `None` answers every unit id, as a TCP device does.
#[derive(Debug, Clone)]
pub struct BankService {
    pub bank: SharedBank,
    pub faults: Arc<Faults>,
    pub unit: Option<u8>,
}

type Reply = Result<Option<Response>, ExceptionCode>;

impl Service for BankService {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Pin<Box<dyn Future<Output = Reply> + Send>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        let this = self.clone();
        Box::pin(async move {
            if let Some(unit) = this.unit
                && req.slave != unit
            {
                return Ok(None);
            }
            let n = this.faults.requests.fetch_add(1, Ordering::Relaxed) + 1;
            let delay = this.faults.delay_ms.load(Ordering::Relaxed);
            if delay > 0 {
                tokio::time::sleep(Duration::from_millis(delay)).await;
            }
            let k = this.faults.exception_every.load(Ordering::Relaxed) as u64;
            let reply = if k > 0 && n.is_multiple_of(k) {
                Err(ExceptionCode::ServerDeviceBusy)
            } else {
                answer(&mut lock(&this.bank), req.request).map(Some)
            };
            if reply.is_err() {
                this.faults.exceptions.fetch_add(1, Ordering::Relaxed);
            }
            reply
        })
    }
}

/// The range `addr..addr + count` of a 65536-entry table, or "illegal data address".
fn range(addr: u16, count: usize) -> Result<std::ops::Range<usize>, ExceptionCode> {
    let start = addr as usize;
    if count == 0 || start + count > 0x1_0000 {
        return Err(ExceptionCode::IllegalDataAddress);
    }
    Ok(start..start + count)
}

/// A request against the bank (Modbus spec §6).
fn answer(bank: &mut RegisterBank, request: Request<'_>) -> Result<Response, ExceptionCode> {
    match request {
        Request::ReadHoldingRegisters(a, n) => {
            Ok(Response::ReadHoldingRegisters(bank.holding[range(a, n as usize)?].to_vec()))
        }
        Request::ReadInputRegisters(a, n) => {
            Ok(Response::ReadInputRegisters(bank.input[range(a, n as usize)?].to_vec()))
        }
        Request::ReadCoils(a, n) => Ok(Response::ReadCoils(bank.coils[range(a, n as usize)?].to_vec())),
        Request::WriteSingleCoil(a, v) => {
            bank.coils[a as usize] = v;
            Ok(Response::WriteSingleCoil(a, v))
        }
        Request::WriteMultipleCoils(a, v) => {
            let r = range(a, v.len())?;
            bank.coils[r].copy_from_slice(&v);
            Ok(Response::WriteMultipleCoils(a, v.len() as u16))
        }
        Request::WriteSingleRegister(a, v) => {
            bank.holding[a as usize] = v;
            Ok(Response::WriteSingleRegister(a, v))
        }
        Request::WriteMultipleRegisters(a, v) => {
            let r = range(a, v.len())?;
            bank.holding[r].copy_from_slice(&v);
            Ok(Response::WriteMultipleRegisters(a, v.len() as u16))
        }
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

/// A Modbus TCP server that can be stopped and restarted on the same address.
#[derive(Debug)]
pub struct TcpServer {
    addr: SocketAddr,
    service: BankService,
    task: Option<JoinHandle<()>>,
}

impl TcpServer {
    /// Listen on `addr` (port 0 picks a free port; [`TcpServer::addr`] tells which).
    pub async fn start(addr: SocketAddr, service: BankService) -> io::Result<TcpServer> {
        let mut server = TcpServer { addr, service, task: None };
        server.listen().await?;
        Ok(server)
    }

    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    pub fn is_running(&self) -> bool {
        self.task.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Close the listener and every connection (the link is lost).
    pub fn stop(&mut self) {
        if let Some(task) = self.task.take() {
            task.abort();
        }
    }

    /// Listen again on the same address.
    pub async fn restart(&mut self) -> io::Result<()> {
        self.stop();
        self.listen().await
    }

    async fn listen(&mut self) -> io::Result<()> {
        let listener = TcpListener::bind(self.addr).await?;
        self.addr = listener.local_addr()?;
        let service = self.service.clone();
        self.task = Some(tokio::spawn(async move {
            let server = TcpModbusServer::new(listener);
            let on_connected = |stream, socket_addr| {
                let service = service.clone();
                async move { accept_tcp_connection(stream, socket_addr, move |_| Ok(Some(service.clone()))) }
            };
            // Dropping this future (stop) closes the listener and cancels every connection.
            if let Err(e) = server.serve(&on_connected, |e| tracing::debug!("modbus server connection: {e}")).await {
                tracing::warn!("modbus server stopped: {e}");
            }
        }));
        Ok(())
    }
}

impl Drop for TcpServer {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Serve RTU on a serial stream (a port, or one end of a pty pair) until aborted or the
/// stream ends.
pub fn serve_rtu(serial: tokio_serial::SerialStream, service: BankService) -> JoinHandle<io::Result<()>> {
    tokio::spawn(async move { tokio_modbus::server::rtu::Server::new(serial).serve_forever(service).await })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_against_the_bank() {
        let mut bank = RegisterBank::default();
        bank.holding[10] = 7;
        assert_eq!(
            answer(&mut bank, Request::ReadHoldingRegisters(9, 2)),
            Ok(Response::ReadHoldingRegisters(vec![0, 7]))
        );
        assert_eq!(answer(&mut bank, Request::WriteSingleCoil(3, true)), Ok(Response::WriteSingleCoil(3, true)));
        assert!(bank.coils[3]);
        // Past the end of the address space, and zero registers, are illegal addresses.
        assert_eq!(answer(&mut bank, Request::ReadInputRegisters(0xFFFF, 2)), Err(ExceptionCode::IllegalDataAddress));
        assert_eq!(answer(&mut bank, Request::ReadInputRegisters(0, 0)), Err(ExceptionCode::IllegalDataAddress));
        assert_eq!(answer(&mut bank, Request::ReportServerId), Err(ExceptionCode::IllegalFunction));
    }

    #[tokio::test]
    async fn every_kth_request_is_an_exception_and_other_units_are_ignored() {
        let faults = Arc::new(Faults::default());
        faults.set_exception_every(3);
        let s = BankService { bank: shared_bank(), faults: faults.clone(), unit: Some(5) };
        let req = |slave| SlaveRequest { slave, request: Request::ReadHoldingRegisters(0, 1) };
        assert!(s.call(req(5)).await.is_ok());
        assert!(s.call(req(5)).await.is_ok());
        assert_eq!(s.call(req(5)).await, Err(ExceptionCode::ServerDeviceBusy));
        assert_eq!(s.call(req(6)).await, Ok(None), "another slave's request gets no reply");
        assert_eq!(faults.exceptions.load(Ordering::Relaxed), 1);
    }
}
