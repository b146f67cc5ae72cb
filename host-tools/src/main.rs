fn main() -> std::process::ExitCode {
    hammer_host::cli::main()
}
