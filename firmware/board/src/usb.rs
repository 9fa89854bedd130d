//! The host link on USB full-speed CDC-ACM (a virtual serial port on the host: `/dev/ttyACM*`,
//! `host demo --source serial:/dev/ttyACM0`), in the thread-mode executor below the tick. It
//! only moves bytes between the USB endpoints and the link's [`DriverEnd`]: outgoing frames
//! (encoded by [`DriverEnd::take_tx`] here, in thread mode) in 64-byte packets as the host takes
//! them, received packets decoded into commands for the incoming queue
//! ([`DriverEnd::put_rx`], also here in thread mode). The tick never waits on it: when the host is
//! slow or absent, whole messages are dropped on the tick's side and counted (`tx_dropped`).
//! Each time the host opens its port (DTR rises: after enumeration, a cable pulled and plugged
//! back, a host program that closed and reopened the port) the link starts clean
//! ([`DriverEnd::connected`]): a frame torn by the disconnect is dropped, and so is what was
//! queued for the previous connection.

use core::cell::RefCell;

use embassy_futures::join::join4;
use embassy_time::Timer;
use embassy_usb::class::cdc_acm::{CdcAcmClass, ControlChanged, Receiver, Sender, State};
use embassy_usb::driver::EndpointError;
use embassy_usb::{Builder, Config};
use firmware::link::DriverEnd;
use static_cell::StaticCell;

use crate::board::{BOARD, UsbDriver};

/// Full-speed bulk packets.
const PACKET: usize = 64;

/// The USB device and the link's driver end; never returns.
#[embassy_executor::task]
pub async fn run(driver: UsbDriver, link: DriverEnd<'static>) {
    static CONFIG_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State<'static>> = StaticCell::new();

    let (vid, pid) = BOARD.usb_vid_pid;
    let (manufacturer, product, serial) = BOARD.usb_strings;
    let mut config = Config::new(vid, pid);
    config.manufacturer = Some(manufacturer);
    config.product = Some(product);
    config.serial_number = Some(serial);
    config.max_power = 100;
    config.max_packet_size_0 = 64;

    let mut builder = Builder::new(
        driver,
        config,
        CONFIG_DESCRIPTOR.init([0; 256]),
        BOS_DESCRIPTOR.init([0; 256]),
        &mut [],
        CONTROL.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), PACKET as u16);
    let mut device = builder.build();
    let (tx, rx, control) = class.split_with_control();
    // Both directions and the connection watch use the driver end from this one task; none
    // holds the borrow across an `await`, so a borrow never finds it taken.
    let link = RefCell::new(link);
    join4(
        device.run(),
        send(tx, &link),
        receive(rx, &link),
        connections(control, &link),
    )
    .await;
}

/// Every time the host opens the port (DTR rises; a USB reset or unplug lowers it), the link
/// starts clean ([`DriverEnd::connected`]).
async fn connections(control: ControlChanged<'static>, link: &RefCell<DriverEnd<'static>>) {
    let mut open = false;
    loop {
        control.control_changed().await;
        let dtr = control.dtr();
        if dtr
            && !open
            && let Ok(mut l) = link.try_borrow_mut()
        {
            l.connected();
        }
        open = dtr;
    }
}

/// Outgoing: take what the tick queued, one packet at a time, as fast as the host reads.
async fn send(mut tx: Sender<'static, UsbDriver>, link: &RefCell<DriverEnd<'static>>) {
    let mut packet = [0u8; PACKET];
    loop {
        tx.wait_connection().await;
        loop {
            let n = link
                .try_borrow_mut()
                .map_or(0, |mut l| l.take_tx(&mut packet));
            if n == 0 {
                // Nothing queued: look again next millisecond (the tick queues at most once a
                // tick).
                Timer::after_millis(1).await;
                continue;
            }
            let out = packet.get(..n).unwrap_or(&[]);
            if let Err(EndpointError::Disabled) = tx.write_packet(out).await {
                // Unplugged or reset mid-frame: the host's decoder drops the torn frame.
                break;
            }
            // A full packet with nothing after it: a zero-length packet ends the transfer so
            // the host delivers it now.
            let more = link.try_borrow().map_or(true, |l| l.has_tx());
            if n == PACKET && !more && tx.write_packet(&[]).await.is_err() {
                break;
            }
        }
    }
}

/// Incoming: every packet the host sends is decoded, its commands queued for the tick.
async fn receive(mut rx: Receiver<'static, UsbDriver>, link: &RefCell<DriverEnd<'static>>) {
    let mut packet = [0u8; PACKET];
    loop {
        rx.wait_connection().await;
        loop {
            match rx.read_packet(&mut packet).await {
                Ok(n) => {
                    if let Ok(mut l) = link.try_borrow_mut() {
                        l.put_rx(packet.get(..n).unwrap_or(&[]));
                    }
                }
                Err(EndpointError::Disabled) => break,
                // A packet longer than the buffer cannot come from a 64-byte endpoint.
                Err(EndpointError::BufferOverflow) => {}
            }
        }
    }
}
