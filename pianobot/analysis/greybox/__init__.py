"""The one grey-box fitter: keystrokes loaded from runs, the model's free parameters (`layout`),
the simulated forward pass, the criterion and the fit; identify and discover configure it."""
