//! On-target test suite: runs `gyro_sim::checks` inside QEMU. The digest
//! checks compare with the golden values the host also matches, so a pass
//! here means host and Cortex-M4 agree bit for bit. Exit code 0 only if
//! every check passes.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_semihosting as _;
use gyro_sim::checks;
use gyro_sim::qemu::exit;

#[entry]
fn main() -> ! {
    let (pass, fail) = checks::run_all(&mut |name, ok| {
        if ok {
            defmt::info!("ok   {=str}", name);
        } else {
            defmt::error!("FAIL {=str}", name);
        }
    });
    defmt::info!("{=u32} passed, {=u32} failed", pass, fail);
    exit(fail == 0 && pass > 0)
}
