//! PCL storage and loss moduli against temperature: the paper's Table 2 as named tables.
//!
//! Values are effective tensile moduli of the device in kPa at 22, 40, 50 and 60 °C [PAPER, Table 2].
//! The printed table reads as a 1000x collapse of E' between 22 and 40 °C while E'' rises, which is
//! not physical for semicrystalline PCL; reading the small entries as MPa gives smooth trends and
//! E'' > E' above ~40 °C as the paper's text says [EST, docs/physics.md §4]. Both readings exist here;
//! the repaired experimental one is the default.

/// Temperatures of the table rows, °C [PAPER].
pub const TABLE_TEMPERATURES_C: [f64; 4] = [22.0, 40.0, 50.0, 60.0];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaterialTable {
    /// Experimental columns, small entries read as MPa (default) [EST repair of PAPER].
    RepairedExperimental = 1,
    /// Experimental columns exactly as printed [PAPER].
    PrintedExperimental = 2,
    /// Estimated columns, repaired [EST repair of PAPER].
    RepairedEstimated = 3,
    /// Estimated columns exactly as printed [PAPER].
    PrintedEstimated = 4,
}

impl MaterialTable {
    pub const ALL: [MaterialTable; 4] = [
        MaterialTable::RepairedExperimental,
        MaterialTable::PrintedExperimental,
        MaterialTable::RepairedEstimated,
        MaterialTable::PrintedEstimated,
    ];

    pub fn from_index(i: i32) -> Option<Self> {
        Self::ALL.into_iter().find(|t| *t as i32 == i)
    }

    pub fn name(self) -> &'static str {
        match self {
            MaterialTable::RepairedExperimental => "repaired_experimental",
            MaterialTable::PrintedExperimental => "printed_experimental",
            MaterialTable::RepairedEstimated => "repaired_estimated",
            MaterialTable::PrintedEstimated => "printed_estimated",
        }
    }

    /// (E' kPa, E'' kPa) at each row of [`TABLE_TEMPERATURES_C`].
    pub fn rows_kpa(self) -> ([f64; 4], [f64; 4]) {
        match self {
            MaterialTable::RepairedExperimental => ([985.34, 920.0, 400.0, 180.0], [834.45, 1820.0, 1230.0, 120.0]),
            MaterialTable::PrintedExperimental => ([985.34, 0.92, 0.4, 0.18], [834.45, 1820.0, 1.23, 0.12]),
            MaterialTable::RepairedEstimated => ([1000.0, 900.0, 250.0, 20.0], [1000.0, 1800.0, 1000.0, 100.0]),
            MaterialTable::PrintedEstimated => ([1000.0, 0.9, 0.25, 0.02], [1000.0, 1800.0, 1.0, 0.1]),
        }
    }

    /// Storage and loss modulus in Pa at `temperature_c`, linear in log E between rows and held
    /// at the end rows outside 22–60 °C (no data there; the melt above 60 °C is not extrapolated).
    pub fn moduli_pa(self, temperature_c: f64) -> (f64, f64) {
        let (e1, e2) = self.rows_kpa();
        (log_interp(&e1, temperature_c) * 1e3, log_interp(&e2, temperature_c) * 1e3)
    }
}

fn log_interp(values: &[f64; 4], t: f64) -> f64 {
    let ts = &TABLE_TEMPERATURES_C;
    if t <= ts[0] {
        return values[0];
    }
    if t >= ts[3] {
        return values[3];
    }
    let i = (0..3).find(|&i| t <= ts[i + 1]).unwrap_or(2);
    let w = (t - ts[i]) / (ts[i + 1] - ts[i]);
    (values[i].ln() * (1.0 - w) + values[i + 1].ln() * w).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_rows_are_reproduced_exactly_at_their_temperatures() {
        for table in MaterialTable::ALL {
            let (e1, e2) = table.rows_kpa();
            for (i, &t) in TABLE_TEMPERATURES_C.iter().enumerate() {
                let (s, l) = table.moduli_pa(t);
                assert!((s / 1e3 - e1[i]).abs() < 1e-9 * e1[i], "{table:?} E' at {t}");
                assert!((l / 1e3 - e2[i]).abs() < 1e-9 * e2[i], "{table:?} E'' at {t}");
            }
        }
    }

    #[test]
    fn interpolation_is_geometric_mean_halfway() {
        let (e1, _) = MaterialTable::RepairedExperimental.rows_kpa();
        let (s, _) = MaterialTable::RepairedExperimental.moduli_pa(55.0);
        assert!((s / 1e3 - (e1[2] * e1[3]).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn repaired_storage_modulus_falls_monotonically() {
        let mut last = f64::INFINITY;
        for k in 0..=80 {
            let (s, _) = MaterialTable::RepairedExperimental.moduli_pa(20.0 + 0.5 * k as f64);
            assert!(s <= last);
            last = s;
        }
    }
}
