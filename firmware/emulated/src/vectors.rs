//! The interrupt half of the vector table, which a PAC would normally supply.
//!
//! QEMU's mps2-an386 gives the NVIC 32 external interrupts (hw/arm/mps2.c,
//! `num-irq` 32). This board uses UART0's two, TIMER0's and one for its sampling executor; every other line points at
//! cortex-m-rt's `DefaultHandler`, so an unexpected interrupt ends up in a
//! known place instead of jumping through a null vector.

use cortex_m::interrupt::InterruptNumber;

/// The external interrupts this board enables, numbered as QEMU wires them:
/// UART0 RX to IRQ 0 and TX to IRQ 1 (`uartirq[] = {0, 2, 4, 18, 20}`, TX
/// one above RX). UART0's overflow line (ORed into IRQ 12) is left disabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum Interrupt {
    Uart0Rx = 0,
    Uart0Tx = 1,
    /// TIMER0 (`cmsdk_apb_timer_create(0x40000000, … 8)`): the ADC's DMA halves.
    Timer0 = 8,
    /// No device drives it: pended by software to poll the sampling
    /// task's executor (`executor.rs`).
    Dsp = 31,
}

// SAFETY: the discriminants are valid IRQ numbers on this board (< 32).
unsafe impl InterruptNumber for Interrupt {
    fn number(self) -> u16 {
        self as u16
    }
}

/// External interrupt lines modelled for the AN386 image.
const IRQ_COUNT: usize = 32;

extern "C" {
    /// cortex-m-rt's catch-all handler.
    fn DefaultHandler();
}

#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [unsafe extern "C" fn(); IRQ_COUNT] = {
    let mut table: [unsafe extern "C" fn(); IRQ_COUNT] = [DefaultHandler; IRQ_COUNT];
    table[Interrupt::Uart0Rx as usize] = crate::uart::on_rx_interrupt;
    table[Interrupt::Uart0Tx as usize] = crate::uart::on_tx_interrupt;
    table[Interrupt::Timer0 as usize] = crate::adc::on_timer_interrupt;
    table[Interrupt::Dsp as usize] = crate::executor::on_dsp_interrupt;
    table
};
