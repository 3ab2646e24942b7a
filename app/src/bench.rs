pub fn net_live(_o: &std::path::Path, _s: f64, _q: bool) -> Result<(), String> {
    Err("todo".into())
}
