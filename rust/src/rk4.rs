//! Classical fixed-step fourth-order Runge-Kutta over a flat state vector. It knows nothing of
//! the physics: the right-hand side is a closure `f(c, y, dy)` where `c` in {0, 1/2, 1} is the
//! stage's fraction of the step (the caller maps it to time and input).

/// Stage buffers, allocated once per run.
#[derive(Clone, Debug)]
pub struct Rk4 {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    tmp: Vec<f64>,
}

impl Rk4 {
    pub fn new(dim: usize) -> Self {
        Rk4 { k1: vec![0.0; dim], k2: vec![0.0; dim], k3: vec![0.0; dim], k4: vec![0.0; dim], tmp: vec![0.0; dim] }
    }

    /// Advance `y` by one step `dt`.
    #[inline(always)]
    pub fn step<F: FnMut(f64, &[f64], &mut [f64])>(&mut self, f: &mut F, dt: f64, y: &mut [f64]) {
        let h2 = 0.5 * dt;
        f(0.0, y, &mut self.k1);
        for ((t, &yi), &k) in self.tmp.iter_mut().zip(y.iter()).zip(&self.k1) {
            *t = yi + h2 * k;
        }
        f(0.5, &self.tmp, &mut self.k2);
        for ((t, &yi), &k) in self.tmp.iter_mut().zip(y.iter()).zip(&self.k2) {
            *t = yi + h2 * k;
        }
        f(0.5, &self.tmp, &mut self.k3);
        for ((t, &yi), &k) in self.tmp.iter_mut().zip(y.iter()).zip(&self.k3) {
            *t = yi + dt * k;
        }
        f(1.0, &self.tmp, &mut self.k4);
        let h6 = dt / 6.0;
        for i in 0..y.len() {
            y[i] += h6 * (self.k1[i] + 2.0 * (self.k2[i] + self.k3[i]) + self.k4[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_four_on_harmonic_oscillator() {
        let err = |n: usize| {
            let dt = 10.0 / n as f64;
            let mut y = [1.0, 0.0];
            let mut rk = Rk4::new(2);
            let mut f = |_c: f64, y: &[f64], dy: &mut [f64]| {
                dy[0] = y[1];
                dy[1] = -y[0];
            };
            for _ in 0..n {
                rk.step(&mut f, dt, &mut y);
            }
            (y[0] - 10f64.cos()).abs()
        };
        let order = (err(200) / err(400)).log2();
        assert!((order - 4.0).abs() < 0.1, "order {order}");
    }
}
