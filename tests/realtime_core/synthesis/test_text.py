"""What espeak-ng reads badly, written out as said (realtime_core/synthesis/text.py, normalise_for_speech): a table
of a chatbot's answers -> the text espeak-ng is given, and what is left alone because espeak-ng reads it well.
The phonemes each gave before and after: scripts/text_speech_survey.py (session text50)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.synthesis.text import SentenceChunker, clean_text, normalise_for_speech

REWRITTEN = [
    # URLs: the host alone ("h t t p s colon slash slash docs dot python dot org slash three slash library ...")
    (
        "en",
        "You can find the docs at https://docs.python.org/3/library/re.html.",
        "You can find the docs at docs.python.org.",
    ),
    ("en", "Go to www.github.com/facecast/issues?state=open&sort=new to see them.", "Go to github.com to see them."),
    ("en", "Check http://localhost:8080/api/v1 in your browser.", "Check localhost port 8080 in your browser."),
    ("en", "Read the FAQ at https://example.com/faq#pricing.", "Read the FAQ at example.com."),
    ("en", "See example.com/docs, or <https://example.com>.", "See example.com, or <example.com>."),
    ("en", "Visit http://127.0.0.1:8000/docs now.", "Visit 127 dot 0 dot 0 dot 1 port 8000 now."),
    ("es", "Visita www.ejemplo.es/a?b=c para más.", "Visita ejemplo.es para más."),
    ("es", "Consulta http://localhost:8080/api en tu navegador.", "Consulta localhost puerto 8080 en tu navegador."),
    # dates ("two thousand twenty six dash twelve dash zero seven", "deck seven", "cero siete barra doce barra ...")
    ("en", "The release is scheduled for 2026-12-07.", "The release is scheduled for December 7th, 2026."),
    ("en", "The meeting is on 12/07/2026 at 14:30.", "The meeting is on December 7th, 2026 at 2:30 pm."),
    ("en", "It was due 31/12/2025.", "It was due December 31st, 2025."),  # a field over 12 is the day
    ("en", "It starts Dec 7 at 2:30 pm.", "It starts December 7th at 2:30 pm."),
    ("en", "It starts Dec. 7.", "It starts December 7th."),
    ("en", "The report from Jan 15, 2025 is ready.", "The report from January 15th, 2025 is ready."),
    ("en", "On 7 December 2026 and 3 Dec.", "On the 7th of December 2026 and the 3rd of December."),
    ("es", "La reunión es el 07/12/2026 a las 14:30.", "La reunión es el 7 de diciembre de 2026 a las 14:30."),
    ("es", "La fecha límite es el 2026-12-07.", "La fecha límite es el 7 de diciembre de 2026."),
    ("es", "El 5 dic. 2026 y el 7 dic.", "El 5 de diciembre de 2026 y el 7 de diciembre."),
    # times ("nine zero zero", "nine zero five"; "nueve cero cero", "diez treinta hache")
    ("en", "It's open 9:00-17:00, Mon-Fri.", "It's open 9 o'clock to 5 pm, Monday to Friday."),
    ("en", "The call is at 9:05 am, not 9:00 AM or 00:00.", "The call is at 9 oh 5 am, not 9 AM or midnight."),
    ("es", "Abre de 9:00 a 17:00.", "Abre de 9 a 17."),
    ("es", "Nos vemos a las 9:05.", "Nos vemos a las 9 y 5."),
    ("es", "La Dra. García te atenderá a las 10:30 h.", "La Dra. García te atenderá a las 10:30 horas."),
    # amounts ("dollar five", "dollar nineteen point nine nine", "three point five zero your", "uno euro")
    (
        "en",
        "That costs $5, or $19.99 with shipping.",
        "That costs 5 dollars, or 19 dollars and 99 cents with shipping.",
    ),
    ("en", "The ticket is 3.50 EUR, about €20.", "The ticket is 3 euros and 50 cents, about 20 euros."),
    (
        "en",
        "Raised $5M, then $2.5 billion; $0.99, £3.50, 5 $.",
        "Raised 5 million dollars, then 2.5 billion dollars; 99 cents, 3 pounds and 50 pence, 5 dollars.",
    ),
    ("es", "Cuesta 3,50 € o 20 EUR.", "Cuesta 3 euros con 50 céntimos o 20 euros."),
    ("es", "El precio es de $5, o 1 € y $5 millones.", "El precio es de 5 dólares, o un euro y 5 millones de dólares."),
    # units ("five k m", "twenty degrees C", "tres ge be")
    ("en", "It's a 5 km run and it's 20°C outside.", "It's a 5 kilometer run and it's 20 degrees Celsius outside."),
    ("en", "You need 3 GB of RAM, 1 h and 2.5 kg.", "You need 3 gigabytes of ram, 1 hour and 2.5 kilograms."),
    ("es", "Hace 20ºC y caminamos 5 km en 1 h.", "Hace 20 grados Celsius y caminamos 5 kilómetros en una hora."),
    ("es", "Necesitas 3 GB de memoria.", "Necesitas 3 gigabáits de memoria."),
    # versions ("vee two point one point three", "uve dos ...")
    ("en", "Upgrade to v2.1.3 or later.", "Upgrade to version 2 point 1 point 3 or later."),
    ("es", "Actualiza a la v2.1.3.", "Actualiza a la versión 2.1.3."),
    # phone numbers in English, digit by digit ("five hundred fifty five ... one hundred twenty three dash four ...")
    ("en", "Call +1 (555) 123-4567 or 555-0199.", "Call plus 1, 5 5 5, 1 2 3, 4 5 6 7 or 5 5 5, 0 1 9 9."),
    # ranges ("ten dash twenty", "five ten": the en dash was dropped)
    (
        "en",
        "Expect 10-20 minutes, pages 5–10, $10-$20.",
        "Expect 10 to 20 minutes, pages 5 to 10, 10 dollars to 20 dollars.",
    ),
    ("es", "Tardará entre 10-20 minutos, de lun-vie.", "Tardará entre 10 y 20 minutos, de lunes a viernes."),
    # after "between" a range is "and", as after "entre" ("between 10 to 20 people" was said)
    ("en", "Between 10-20 people, between $10-$20.", "Between 10 and 20 people, between 10 dollars and 20 dollars."),
    # Spanish ordinals ("uno punto o") and abbreviations ("pe ex", "etk", "ee uu")
    ("es", "Llegó en 1.º lugar y ella en 2.ª posición.", "Llegó en primer lugar y ella en segunda posición."),
    ("es", "El 3.er día, 1.º de la lista.", "El tercer día, primero de la lista."),
    ("es", "Trae frutas, p. ej., manzanas, peras, etc.", "Trae frutas, por ejemplo, manzanas, peras, etcétera."),
    ("es", "EE. UU. vs. España, aprox. 5.", "Estados Unidos contra España, aproximadamente 5."),
    ("en", "Cats vs. dogs, approx. 5.", "Cats versus dogs, approximately 5."),
]

KEPT = [  # espeak-ng reads these well (or they are not what they look like): left as written
    ("en", "Email support@example.com or john.doe@company.co.uk."),  # "support at example dot com"
    ("es", "Escríbenos a soporte@ejemplo.com."),  # "soporte arroba ejemplo punto com"
    ("en", "Visit example.com, ASP.NET or Socket.io."),  # a bare host: "example dot com"
    ("en", "The deadline is December 7th, 2026, at 2:30 pm."),
    ("es", "Empieza el 7 de diciembre a las 14:30 y a las 14:05."),  # a 24-hour time: "catorce cero cinco"
    ("en", "Sales grew 12.5% and she finished 1st, he 2nd."),
    ("es", "Las ventas subieron un 12,5%."),
    ("en", "Follow us @facecast and use #MachineLearning. Great job! 🎉"),  # clean_text drops # and emoji
    ("en", "Bring fruit, e.g., apples, pears, etc. Dr. Smith at 9 a.m."),
    ("es", "Llama al +34 912 345 678 o al 912-345-678."),  # Spanish reads phone numbers in groups
    ("en", "Install Node.js, run app.py and open README.md."),  # not domains
    ("en", "5 - 3 = 2, COVID-19, x86-64, GPT-4, 16:9, 25:61, 7/12."),  # a minus, names, a ratio, no time, a date
    # a decimal ("three point one four"), a path ("slash usr slash local ..."), acronyms espeak-ng spells or says
    ("en", "Pi is 3.14 in the 90s, March 2026, the file /usr/local/bin/python, 10/20."),
    ("en", "I think it's OK: the USA, a CPU, a GPU, an API, NASA, AI and an LLM, the LLMs."),
    ("es", "La CPU, la API de la NASA, la ONU, la IA y el USB."),
]


CHATBOT = [  # issue 13: what an LLM avatar's user heard every day (before: espeak-ng's reading of the text as written)
    # versions after a name or a version word ("three point one two", "two point zero point one", "vee one point four")
    ("en", "Python 3.12 is out.", "Python 3 point 12 is out."),
    ("en", "Use version 2.0.1 or v1.4.", "Use version 2 point oh point 1 or version 1 point 4."),
    ("en", "Update to iOS 17.2 and Python 3.12.1.", "Update to iOS 17 point 2 and Python 3 point 12 point 1."),
    ("en", "Pi is 3.14, not 3.12 or 2.05 million.", "Pi is 3.14, not 3.12 or 2.05 million."),  # decimals stay
    ("en", "Visit 192.168.1.10 now.", "Visit 192 dot 168 dot 1 dot 10 now."),  # "one hundred ... point one six eight"
    # fractions and scores ("three slash four"); a date stays one
    ("en", "Add 3/4 cup of flour and 1/2 cup sugar.", "Add 3 quarters cup of flour and a half cup sugar."),
    ("en", "Use 1 1/2 cups, 2/3 of it.", "Use 1 and a half cups, 2 thirds of it."),
    (
        "en",
        "On 3/4/2025 it was rated 4.5/5, then 10/10.",
        "On March 4th, 2025 it was rated 4.5 out of 5, then 10 out of 10.",
    ),
    ("es", "Añade 3/4 de taza y 1/2 taza.", "Añade 3 cuartos de taza y media taza."),
    (
        "es",
        "Solo 1/3 del total, 1 1/2 kilos, el 3/4/2025.",
        "Solo un tercio del total, 1 y medio kilos, el 3 de abril de 2025.",
    ),
    # a range is no phone number ("one zero zero, two zero zero zero"); a toll-free one is ("one dash eight hundred")
    ("en", "Values 100-2000 or 500-1000.", "Values 100 to 2000 or 500 to 1000."),
    ("en", "Call 1-800-555-0199.", "Call 1, 8 hundred, 5 5 5, 0 1 9 9."),
    # times ("seventeen hundred", "fourteen thirty", "nine a m five p m": the en dash was dropped)
    ("en", "Open 9:00-17:00, lunch 12:30-14:05.", "Open 9 o'clock to 5 pm, lunch 12:30 to 2 oh 5 pm."),
    ("en", "Mon–Fri 9am–5pm, Sat 10-2 pm.", "Monday to Friday 9am to 5pm, Sat 10 to 2 pm."),
    # "twenty four slash seven", "eks two", "two eks", "one eks one", "we're one", "I E", "first third" (a pause)
    ("en", "We're open 24/7, a 50/50 split.", "We're open 24 7, a 50 50 split."),
    ("en", "Speed x2, 10x faster, 1920x1080, 3 x 4.", "Speed times 2, 10 times faster, 1920 by 1080, 3 times 4."),
    ("en", "We're #1 in C# and F#.", "We're number 1 in C sharp and F sharp."),
    ("en", "Red ones, i.e. ripe, came 1st-3rd.", "Red ones, that is ripe, came 1st to 3rd."),
    # "five ... ten" (the marks silent), "five minutes" (clean_text drops ~ < >)
    ("en", "He is 5'10\" tall, she 5’4”.", "He is 5 foot 10 tall, she 5 foot 4."),
    (
        "en",
        "Wait ~5 minutes for >50 users, <10 ms.",
        "Wait about 5 minutes for more than 50 users, less than 10 milliseconds.",
    ),
    # capitals espeak-ng spells ("R A M", "P I N", "T O O", "B I G") or says ("eeta", "imho")
    ("en", "Add RAM, a SIM and your PIN; PINs.", "Add ram, a sim and your pin; pins."),
    ("en", "It is TOO big, a BIG deal; do NOT wait.", "It is too big, a big deal; do not wait."),
    ("en", "The ETA, IMHO, is near.", "The E.T.A., I.M.H.O., is near."),
    ("es", "Abierto 24/7, somos el #1.", "Abierto 24 7, somos el número 1."),
    ("es", "NO lo hagas, es MUY importante, x2 más rápido.", "no lo hagas, es muy importante, por 2 más rápido."),
    ("es", "Rojas, i.e. maduras, del 1.º-3.º", "Rojas, es decir maduras, del primero a tercero"),
]


def test_chatbot_text_is_written_out_as_a_person_says_it():
    for language, text, said in CHATBOT:
        assert normalise_for_speech(text, language=language) == said, text


_MISREAD = re.compile(r"\d\s?[/#x'\"’”~<>–]|[/#~<>]\s?\d|(?<![a-z])x\d|\d-\d")
"""What espeak-ng misreads next to a digit: a slash, a hash, "x", a foot or inch mark, a dropped sign, a hyphen between
numbers (a range, a phone number)."""
_MISREAD_EN = re.compile(r"\d\.\d+\.\d|(?:[A-Z]\w*|version)\s\d+\.\d\d")
"""And in English: a dotted triple ("two point zero point one"), a version's two-digit part ("three point one two")."""


@pytest.mark.parametrize(("language", "text", "said"), CHATBOT + REWRITTEN)
def test_a_rewrite_leaves_no_number_espeak_misreads_and_a_second_pass_changes_nothing(language, text, said):
    """Invariants over every case: the numbers left are the plain ones espeak-ng reads as a person would (each
    'said' above is the expectation; this checks the form of all of them), and normalising is idempotent (a
    sentence normalised twice, by a retry or by clean_text after a caller normalised, is said the same)."""
    out = normalise_for_speech(text, language=language)
    assert not _MISREAD.search(out), out
    assert language != "en" or not _MISREAD_EN.search(out), out
    assert normalise_for_speech(out, language=language) == out


@pytest.mark.parametrize(("language", "text"), KEPT)
def test_a_kept_text_is_kept_by_a_second_pass_too(language, text):
    assert normalise_for_speech(normalise_for_speech(text, language=language), language=language) == text


@pytest.mark.parametrize(("language", "text", "said"), REWRITTEN)
def test_what_espeak_reads_badly_is_written_out_as_said(language, text, said):
    assert normalise_for_speech(text, language=language) == said


@pytest.mark.parametrize(("language", "text"), KEPT)
def test_what_espeak_reads_well_is_left_as_written(language, text):
    assert normalise_for_speech(text, language=language) == text


def test_an_ambiguous_numeric_date_follows_the_voice_and_an_unambiguous_one_does_not():
    """'07/12/2026' is July 12 to a US voice and 7 December to a British or Spanish one; '31/12/2025' and
    '12/31/2025' are the same day to all."""
    assert normalise_for_speech("07/12/2026", language="en") == "July 12th, 2026"
    assert normalise_for_speech("07/12/2026", language="en", day_first=True) == "December 7th, 2026"
    assert normalise_for_speech("07/12/2026", language="es") == "7 de diciembre de 2026"
    for day_first in (False, True):
        for text in ("31/12/2025", "12/31/2025", "2025-12-31"):
            assert normalise_for_speech(text, language="en", day_first=day_first) == "December 31st, 2025"
    # not a date: the month or day out of range is left as written
    assert normalise_for_speech("2025-13-01 and 32/01/2025", language="en") == "2025-13-01 and 32/01/2025"


def test_english_ordinal_suffixes_follow_the_number():
    """An independent rule: 1st 2nd 3rd, but 11th 12th 13th, and 21st 22nd 23rd 31st."""
    want = {1: "st", 2: "nd", 3: "rd", 11: "th", 12: "th", 13: "th", 21: "st", 22: "nd", 23: "rd", 31: "st"}
    for day in range(1, 32):
        got = normalise_for_speech(f"May {day}", language="en")
        assert got == f"May {day}{want.get(day, 'th')}"


def test_a_url_leaves_nothing_of_its_path_for_the_cleaning_to_leave_behind():
    """clean_text drops '#' and '_' as markdown: without the normalisation first, '/faq#pricing' and
    '/wiki/Speech_synthesis' left 'faq pricing' and 'Speech synthesis' in the speech after the spelled URL."""
    assert clean_text("See https://en.wikipedia.org/wiki/Speech_synthesis#History now.", language="en") == (
        "See en.wikipedia.org now."
    )
    assert clean_text("See [the docs](https://example.com/docs) now.", language="en") == "See the docs now."
    assert clean_text("See https://example.com/docs now.") == "See https://example.com/docs now."  # no language
    with pytest.raises(ConfigError, match="unsupported language 'fr'"):
        clean_text("Voir https://example.com.", language="fr")


def test_a_month_or_spanish_abbreviation_before_a_number_or_lower_case_word_ends_no_sentence():
    """'It starts Dec. 7 at noon.' was cut after 'Dec.' (two sentences, ~0.45 s of silence between, and 'Dec.'
    alone read 'deck'); the same chunks whatever the chunking."""
    text = "It starts Dec. 7 at noon. Trae frutas, p. ej. manzanas. Viaja a EE. UU. mañana. Then more."
    want = ["It starts Dec. 7 at noon.", "Trae frutas, p. ej. manzanas.", "Viaja a EE. UU. mañana.", "Then more."]
    rng = np.random.default_rng(0)
    for k in range(10):
        c, got = SentenceChunker(), []
        cuts = np.sort(rng.choice(len(text), 6, replace=False)) if k else []
        for piece in np.split(np.array(list(text)), cuts):
            got += c.push("".join(piece))
        assert got + c.flush() == want
