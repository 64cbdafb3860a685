//! A closed stdout (`gyro … | head`, an evaluation piped to `head`): the
//! reader has what it wanted, so the program stops quietly with success,
//! as Unix tools do, instead of panicking in `print!`.

/// Whether a panic's payload is `print!`'s on a closed pipe.
pub fn broken_pipe(payload: &(dyn std::any::Any + Send)) -> bool {
    let msg = payload
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| payload.downcast_ref::<&str>().copied())
        .unwrap_or("");
    msg.contains("failed printing to stdout") && msg.contains("Broken pipe")
}

/// From here on, `print!` on a closed pipe ends the program with exit
/// code 0 and no message; every other panic is reported as before.
pub fn quiet_on_closed_pipe() {
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if broken_pipe(info.payload()) {
            std::process::exit(0);
        }
        default_hook(info)
    }));
}
