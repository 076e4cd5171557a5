// The sign-in page: says so when the last token was refused (POST /login
// redirects to /?login=failed).
if (new URLSearchParams(window.location.search).get('login') === 'failed') {
  const p = document.getElementById('failed');
  p.textContent = 'That token is not valid (unknown or revoked). Try again.';
  p.hidden = false;
}
